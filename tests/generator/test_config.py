import contextlib
import dataclasses
import io
import json
import math
import pickle
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from generator import ConfigError, SceneConfig, generate_scene_with_stats
from generator.config import CameraConfig, PlacementConfig, TerrainConfig


@pytest.mark.parametrize(
    ("factory", "field"),
    [
        (lambda: PlacementConfig(num_mushrooms=0), "placement.num_mushrooms"),
        (lambda: PlacementConfig(num_mushrooms=-3), "placement.num_mushrooms"),
        (lambda: PlacementConfig(num_mushrooms=101), "placement.num_mushrooms"),
        (lambda: PlacementConfig(scale_range=(2.0, 1.0)), "placement.scale_range"),
        (lambda: PlacementConfig(stretch_range=(math.nan, 1.0)), "placement.stretch_range[0]"),
        (lambda: PlacementConfig(overlap_iou=1.5), "placement.overlap_iou"),
        (lambda: PlacementConfig(overlap_iou=-0.1), "placement.overlap_iou"),
        (lambda: PlacementConfig(max_attempts=0), "placement.max_attempts"),
        (lambda: PlacementConfig(species="green"), "placement.species"),
        (lambda: PlacementConfig(tilt_std_deg=math.inf), "placement.tilt_std_deg"),
        (lambda: TerrainConfig(resolution=1), "terrain.resolution"),
        (lambda: TerrainConfig(size_x=0), "terrain.size_x"),
        (lambda: TerrainConfig(amplitude=math.nan), "terrain.amplitude"),
        (lambda: CameraConfig(preset="kinect"), "camera.preset"),
        (lambda: CameraConfig(znear=3.0), "camera.znear"),
    ],
)
def test_invalid_values_name_the_field(factory, field):
    with pytest.raises(ConfigError) as info:
        factory()
    assert info.value.field == field
    assert field in str(info.value)


def test_patch_too_small_for_count_is_rejected():
    with pytest.raises(ConfigError, match="num_mushrooms"):
        SceneConfig(placement=PlacementConfig(num_mushrooms=100, x_range=(-0.01, 0.01), y_range=(-0.01, 0.01)))


def test_placement_range_outside_terrain_is_rejected():
    with pytest.raises(ConfigError, match="x_range"):
        SceneConfig(placement=PlacementConfig(x_range=(-1.0, 1.0)))


def test_from_dict_round_trip_and_unknown_keys():
    config = SceneConfig().replace(placement__num_mushrooms=12, terrain__octaves=3)
    assert SceneConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ConfigError, match="placement.bogus"):
        SceneConfig.from_dict({"placement": {"bogus": 1}})
    with pytest.raises(ConfigError, match="unknown section"):
        SceneConfig.from_dict({"robot": {}})


def test_yaml_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("placement:\n  num_mushrooms: 7\n  overlap_iou: 0.0\n")
    assert SceneConfig.from_file(str(path)).placement.num_mushrooms == 7
    path.write_text("placement: [1, 2")
    with pytest.raises(ConfigError):
        SceneConfig.from_file(str(path))


def test_crowded_request_terminates_and_reports_count():
    # A small patch at zero overlap tolerance cannot hold 12 big mushrooms: it must stop and say so.
    config = SceneConfig(placement=PlacementConfig(
        num_mushrooms=12, x_range=(-0.04, 0.04), y_range=(-0.04, 0.04), overlap_iou=0.0,
        max_attempts=10, scale_range=(1.5, 2.0)))
    scene, stats = generate_scene_with_stats(config, seed=0)
    assert stats.placed == len(scene.instances) < 12
    assert stats.attempts <= 12 * 10
    assert scene.requested == 12


def test_exponent_floats_read_as_floats(tmp_path):
    # YAML 1.1 wants a dot and a signed exponent: it read 1e-3 as the string '1e-3'.
    (tmp_path / "c.json").write_text('{"placement": {"overlap_iou": 1e-3}, "terrain": {"amplitude": 5E-3}}')
    (tmp_path / "c.yaml").write_text("placement:\n  overlap_iou: 1e-3\n  tilt_std_deg: 1.5e1\n")
    json_config = SceneConfig.from_file(str(tmp_path / "c.json"))
    assert (json_config.placement.overlap_iou, json_config.terrain.amplitude) == (0.001, 0.005)
    yaml_config = SceneConfig.from_file(str(tmp_path / "c.yaml"))
    assert (yaml_config.placement.overlap_iou, yaml_config.placement.tilt_std_deg) == (0.001, 15.0)


@pytest.mark.parametrize(("text", "field"), [
    ("terrain:\n  amplitude: true\n", "terrain.amplitude"),
    ("placement:\n  num_mushrooms: true\n", "placement.num_mushrooms"),
    ("camera:\n  width: false\n", "camera.width"),
    ("placement:\n  x_range: [true, 0.1]\n", "placement.x_range[0]"),
])
def test_booleans_are_not_numbers(tmp_path, text, field):
    (tmp_path / "c.yaml").write_text(text)
    with pytest.raises(ConfigError) as info:
        SceneConfig.from_file(str(tmp_path / "c.yaml"))
    assert info.value.field == field


@pytest.mark.parametrize(("name", "text"), [
    ("c.yaml", "placement:\n  num_mushrooms: 5\n  num_mushrooms: 7\n"),
    ("c.json", '{"placement": {"num_mushrooms": 5, "num_mushrooms": 7}}'),
])
def test_duplicate_keys_are_refused(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    with pytest.raises(ConfigError, match="duplicate key") as info:
        SceneConfig.from_file(str(tmp_path / name))
    assert info.value.field == "placement.num_mushrooms" and name in str(info.value)


def test_undecodable_config_names_the_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_bytes(b"placement:\n  num_mushrooms: \xd0\x00\xff\n")
    with pytest.raises(ConfigError, match="not a UTF-8 text file") as info:
        SceneConfig.from_file(str(path))
    assert info.value.field == str(path)


@pytest.mark.parametrize("value", [[0.1], [0.1, 0.2, 0.3], 0.1, "ab", {"a": 1}, None])
def test_ranges_must_be_pairs(value):
    with pytest.raises(ConfigError, match="pair") as info:
        PlacementConfig(x_range=value)
    assert info.value.field == "placement.x_range"


def test_sizes_that_would_exhaust_memory_are_refused():
    with pytest.raises(ConfigError, match=r"\[2, 1024\]"):
        TerrainConfig(resolution=100_000)  # 100000^2 float64 heights would need 74 GiB
    with pytest.raises(ConfigError, match=r"\[16, 4096\]"):
        CameraConfig(width=100_000)  # MuJoCo cannot make the frame buffer


def test_config_error_survives_pickling():
    # Workers send their errors back pickled; ConfigError's two-argument constructor broke that.
    error = pickle.loads(pickle.dumps(ConfigError("camera.width", "too big")))
    assert (error.field, error.message, str(error)) == ("camera.width", "too big", "camera.width: too big")


def test_sections_must_have_their_types():
    with pytest.raises(ConfigError) as info:
        SceneConfig(placement="many")
    assert info.value.field == "placement"


# Property-based: every field, given a wrong-typed, non-finite or out-of-range value, raises a
# ConfigError naming that field (or an element of it), from a dict and through a config file
# given to the CLI, which then leaves no output folder.

_WRONG_TYPE = st.one_of(st.booleans(), st.none(), st.text(max_size=5), st.lists(st.integers(), max_size=3),
                        st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
_NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])


def _bad_number(lo=None, hi=None, *, lo_open=False):
    """Wrong types, non-finite floats and finite floats outside [lo, hi] (or (lo, hi] if lo_open)."""
    out = [_WRONG_TYPE, _NON_FINITE]
    if lo is not None:
        out.append(st.floats(max_value=lo, exclude_max=not lo_open, allow_nan=False, allow_infinity=False))
    if hi is not None:
        out.append(st.floats(min_value=hi, exclude_min=True, allow_nan=False, allow_infinity=False))
    return st.one_of(*out)


def _bad_int(lo, hi=None):
    out = [_WRONG_TYPE, _NON_FINITE, st.floats(allow_nan=False, allow_infinity=False), st.integers(max_value=lo - 1)]
    if hi is not None:
        out.append(st.integers(min_value=hi + 1))
    return st.one_of(*out)


def _bad_choice(choices):
    return st.one_of(_WRONG_TYPE, st.text(max_size=8).filter(lambda s: s not in choices))


def _bad_range(*, positive):
    number = _bad_number(0, lo_open=True) if positive else _bad_number()
    good = st.floats(0.5, 1.0) if positive else st.floats(-0.1, 0.1)
    return st.one_of(
        _WRONG_TYPE.filter(lambda v: not isinstance(v, list) or len(v) != 2),
        st.lists(good, max_size=5).filter(lambda v: len(v) != 2),
        st.tuples(number, good), st.tuples(good, number),
        st.tuples(st.just(0.09), st.just(0.08)),  # min > max
    ).map(lambda v: list(v) if isinstance(v, tuple) else v)


BAD_VALUES = {
    "terrain.size_x": _bad_number(0, lo_open=True), "terrain.size_y": _bad_number(0, lo_open=True),
    "terrain.resolution": _bad_int(2, 1024), "terrain.amplitude": _bad_number(0),
    "terrain.scale": _bad_number(0, lo_open=True), "terrain.octaves": _bad_int(1, 16),
    "terrain.persistence": _bad_number(0, lo_open=True), "terrain.lacunarity": _bad_number(0, lo_open=True),
    "terrain.base_elevation": _bad_number(),
    "placement.num_mushrooms": _bad_int(1, 100), "placement.species": _bad_choice(("white", "brown", "mixed")),
    "placement.x_range": _bad_range(positive=False), "placement.y_range": _bad_range(positive=False),
    "placement.tilt_std_deg": _bad_number(0, 90),
    "placement.tilt_distribution": _bad_choice(("normal", "half_normal")),
    "placement.scale_range": _bad_range(positive=True), "placement.stretch_range": _bad_range(positive=True),
    "placement.max_attempts": _bad_int(1, 10_000), "placement.overlap_iou": _bad_number(0, 1),
    "placement.neighbours": _bad_int(1, 100), "placement.overlap_solids": _bad_choice(("meshes", "hulls")),
    "placement.insertion_depth": _bad_number(0, 0.02),
    "camera.preset": _bad_choice(("d405", "d435")), "camera.width": _bad_int(16, 4096),
    "camera.height": _bad_int(16, 4096), "camera.height_above_soil": _bad_number(0, lo_open=True),
    "camera.tilt_deg": _bad_number(), "camera.znear": _bad_number(0, lo_open=True),
    "camera.zfar": _bad_number(0, lo_open=True),
}  # fmt: skip

_bad_entry = st.sampled_from(sorted(BAD_VALUES)).flatmap(lambda f: st.tuples(st.just(f), BAD_VALUES[f]))


def test_every_field_has_bad_values():
    fields = {f"{s}.{f.name}" for s, cls in (("terrain", TerrainConfig), ("placement", PlacementConfig),
                                             ("camera", CameraConfig)) for f in dataclasses.fields(cls)}
    assert fields == set(BAD_VALUES)


def _assert_names(error, field):
    assert error.field == field or error.field.startswith(field + "["), (error.field, field)
    assert field in str(error)


@settings(max_examples=300, deadline=None)
@given(_bad_entry)
def test_bad_field_values_raise_naming_the_field(entry):
    field, value = entry
    section, name = field.split(".")
    with pytest.raises(ConfigError) as info:
        SceneConfig.from_dict({section: {name: value}})
    _assert_names(info.value, field)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_bad_entry)
def test_bad_config_files_fail_the_cli_and_leave_nothing(entry):
    from sms3d_env.cli import main

    field, value = entry
    section, name = field.split(".")
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "c.json"
        config.write_text(json.dumps({section: {name: value}}))  # NaN and Infinity as json writes them
        for argv in (["generate", "--num-scenes", "1", "--no-progress"], ["scene"]):
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                assert main([*argv, "--config", str(config), "--out", str(Path(tmp) / "out")]) == 2
            assert field in err.getvalue() and "Traceback" not in err.getvalue()
            assert sorted(p.name for p in Path(tmp).iterdir()) == ["c.json"]


@pytest.mark.parametrize("name", ["depth_noise_subpixel", "edge_threshold", "edge_hole_probability",
                                  "camera_height_jitter", "camera_tilt_jitter_deg"])
def test_realism_numbers_refuse_booleans(name):
    from generator.dataset.options import RealismOptions

    with pytest.raises(ConfigError) as info:
        RealismOptions(**{name: True})
    assert info.value.field == f"realism.{name}"
