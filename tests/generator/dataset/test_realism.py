"""The stereo depth camera model and RGB sensor effects of ``generator.dataset.realism``:
statistics against the formulas of docs/physics.md (cameras), seeding, the records in
``scene.json``, option validation, and that the older options reproduce their old output."""

import dataclasses
import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from generator import SceneConfig, generate_scene
from generator.dataset import DatasetOptions, RealismOptions
from generator.dataset.options import CAMERA_MODEL_FIELDS, CAMERA_MODEL_SWITCHES, STEREO_BASELINE_M
from generator.dataset.realism import (
    apply_depth_realism,
    apply_rgb_realism,
    correlated_unit_noise,
    stereo_shadow_mask,
)
from generator.dataset.render import SceneRenderer
from generator.dataset.seeds import realism_rng
from generator.errors import ConfigError

F = 382.0  # d405 focal length at 640 x 480, px
B = STEREO_BASELINE_M["d405"]


def _old_apply_depth_realism(depth, focal_px, preset, options, rng):
    """``apply_depth_realism`` as it was before the camera model, verbatim."""
    depth = depth.astype(np.float64, copy=True)
    valid = depth > 0
    if options.depth_noise:
        sigma = depth**2 * options.depth_noise_subpixel / (focal_px * STEREO_BASELINE_M[preset])
        depth = np.where(valid, depth + sigma * rng.standard_normal(depth.shape), 0.0)
    if options.edge_holes:
        padded = np.pad(depth, 1, mode="edge")
        step = np.zeros_like(depth)
        for dv, du in ((0, 1), (1, 0), (0, -1), (-1, 0)):
            neighbour = padded[1 + dv:1 + dv + depth.shape[0], 1 + du:1 + du + depth.shape[1]]
            step = np.maximum(step, np.abs(depth - neighbour))
        edges = cv2.dilate((step > options.edge_threshold).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        holes = edges & (rng.random(depth.shape) < options.edge_hole_probability)
        depth[holes] = 0.0
    depth[~valid] = 0.0
    return np.clip(depth, 0.0, None).astype(np.float32)


def _bed(h=96, w=128, seed=0):
    """A soil plane at 0.40 m with nearer boxes (caps) at 0.30-0.36 m and a few invalid pixels."""
    rng = np.random.default_rng(seed)
    depth = 0.40 + 0.001 * rng.standard_normal((h, w))
    for _ in range(6):
        v, u = rng.integers(0, h - 20), rng.integers(0, w - 20)
        depth[v:v + rng.integers(8, 20), u:u + rng.integers(8, 20)] = rng.uniform(0.30, 0.36)
    depth[:2, :5] = 0.0
    return depth.astype(np.float32)


def _state(rng):
    return rng.bit_generator.state


# --- the older options are untouched ---------------------------------------------------------

@pytest.mark.parametrize("old", [{}, {"depth_noise": True}, {"edge_holes": True},
                                 {"depth_noise": True, "edge_holes": True, "lighting": True, "soil": True,
                                  "camera_jitter": True}])
def test_old_options_give_the_old_depth_and_draws(old):
    depth = _bed()
    options = RealismOptions(**old)
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    new, drawn = apply_depth_realism(depth, F, "d405", options, a)
    ref = _old_apply_depth_realism(depth, F, "d405", options, b)
    assert new.tobytes() == ref.tobytes() and drawn == {}
    assert _state(a) == _state(b)  # the same draws, so later draws are the same too


def test_rgb_effects_off_draw_nothing_and_change_nothing():
    rgb = np.random.default_rng(0).integers(0, 256, (24, 32, 3), dtype=np.uint8)
    rng = np.random.default_rng(5)
    before = _state(rng)
    out, drawn = apply_rgb_realism(rgb, RealismOptions(depth_noise=True, lighting=True), rng)
    assert out is rgb and drawn == {} and _state(rng) == before


def test_old_options_record_the_old_settings():
    old = RealismOptions(depth_noise=True, edge_holes=True)
    assert set(old.to_dict()) == {f.name for f in dataclasses.fields(RealismOptions)} - set(CAMERA_MODEL_FIELDS)
    assert "realism" in DatasetOptions(realism=old).to_dict()
    assert set(DatasetOptions(realism=old).to_dict()["realism"]) == set(old.to_dict())
    new = RealismOptions(flying_pixels=True, matching_window_px=5)
    assert new.to_dict()["matching_window_px"] == 5
    assert DatasetOptions.from_dict(DatasetOptions(realism=new).to_dict()).realism == new
    assert DatasetOptions.from_dict(DatasetOptions(realism=old).to_dict()).realism == old


def test_switches_are_off_by_default_and_any_sees_each():
    assert not RealismOptions().any
    for name in CAMERA_MODEL_SWITCHES:
        assert getattr(RealismOptions(), name) is False
        assert RealismOptions(**{name: True}).any


# --- correlated disparity noise ----------------------------------------------------------------

def test_correlated_noise_per_pixel_std_follows_the_stereo_formula():
    """Across independent frames, each pixel's depth std is z^2 s / (f B) (a depth ramp)."""
    h, w, frames = 32, 48, 300
    z = np.tile(np.linspace(0.15, 0.50, w), (h, 1)).astype(np.float32)
    options = RealismOptions(correlated_noise=True, depth_noise=True)  # depth_noise is replaced
    rng = np.random.default_rng(11)
    stack = np.stack([apply_depth_realism(z, F, "d405", options, rng)[0] for _ in range(frames)]).astype(np.float64)
    sigma = z.astype(np.float64) ** 2 * options.depth_noise_subpixel / (F * B)
    ratio = stack.std(axis=0) / sigma
    assert abs(ratio.mean() - 1.0) < 0.02  # pooled over all pixels
    near, far = ratio[:, :8].mean(), ratio[:, -8:].mean()  # the z^2 law holds at both ends
    assert abs(near - 1.0) < 0.04 and abs(far - 1.0) < 0.04
    assert abs((stack.mean(axis=0) - z).mean() / sigma.mean()) < 0.05  # no bias to first order


@pytest.mark.parametrize(("window", "expected"), [(7, 6 / 7), (1, 0.0)])
def test_correlated_noise_neighbour_correlation(window, expected):
    z = np.full((240, 320), 0.4, np.float32)
    out, drawn = apply_depth_realism(z, F, "d405", RealismOptions(correlated_noise=True, matching_window_px=window),
                                     np.random.default_rng(2))
    e = out.astype(np.float64) - 0.4
    horizontal = np.corrcoef(e[:, :-1].ravel(), e[:, 1:].ravel())[0, 1]
    vertical = np.corrcoef(e[:-1].ravel(), e[1:].ravel())[0, 1]
    assert abs(horizontal - expected) < 0.03 and abs(vertical - expected) < 0.03
    rec = drawn["correlated_noise"]
    assert rec["window_px"] == window and rec["pixels"] == e.size and rec["replaces_depth_noise"] is False
    assert abs(rec["realised_std_px"] - 0.08) < 0.006


def test_unit_noise_has_unit_std_for_any_window():
    for window in (1, 2, 4, 7):
        field = correlated_unit_noise((200, 200), window, np.random.default_rng(window))
        assert field.shape == (200, 200) and abs(field.std() - 1.0) < 0.06


# --- disparity quantisation --------------------------------------------------------------------

def test_quantised_depth_lies_on_the_disparity_grid():
    z = np.random.default_rng(1).uniform(0.15, 0.5, (64, 64)).astype(np.float32)
    z[0, :4] = 0.0
    options = RealismOptions(disparity_quantisation=True)
    out, drawn = apply_depth_realism(z, F, "d405", options, np.random.default_rng(0))
    ok = out > 0
    assert (ok == (z > 0)).all()
    steps = F * B / out[ok].astype(np.float64) / options.disparity_step_px
    assert np.abs(steps - np.rint(steps)).max() < 1e-3
    # within half a step of the true disparity
    assert np.abs(F * B / out[ok] - F * B / z[ok]).max() <= options.disparity_step_px / 2 + 1e-4
    rec = drawn["disparity_quantisation"]
    assert rec["step_px"] == 1 / 32 and rec["pixels"] == ok.sum() and rec["levels"] == np.unique(np.rint(steps)).size


# --- flying pixels -----------------------------------------------------------------------------

def test_flying_pixels_only_at_edges_and_between_near_and_far():
    depth = _bed()
    d = depth.astype(np.float64)
    options = RealismOptions(flying_pixels=True)
    out, drawn = apply_depth_realism(depth, F, "d405", options, np.random.default_rng(4))
    changed = out != depth
    assert changed.sum() == drawn["flying_pixels"]["pixels"] > 20
    def cross(fill):  # each pixel and its 4 neighbours, invalid ones as ``fill``
        pad = np.pad(np.where(d > 0, d, fill), 1, constant_values=fill)
        return np.stack([pad[1 + a:1 + a + d.shape[0], 1 + b:1 + b + d.shape[1]]
                         for a, b in ((0, 0), (0, 1), (1, 0), (0, -1), (-1, 0))])

    near, far = cross(np.inf).min(axis=0), cross(-np.inf).max(axis=0)
    assert (far - near > options.edge_threshold)[changed].all()  # only at depth edges
    tol = 1e-6
    assert ((out >= near - tol) & (out <= far + tol))[changed].all()
    edge_pixels = drawn["flying_pixels"]["edge_pixels"]
    assert abs(drawn["flying_pixels"]["pixels"] / edge_pixels - 0.5) < 0.1  # probability 0.5
    assert (out[d == 0] == 0).all()


# --- stereo shadows ----------------------------------------------------------------------------

@pytest.mark.parametrize(("preset", "z_near", "z_far"), [("d405", 0.30, 0.40), ("d435", 0.25, 0.40),
                                                          ("d405", 0.10, 0.40)])
def test_stereo_shadow_band_on_a_step(preset, z_near, z_far):
    baseline = STEREO_BASELINE_M[preset]
    depth = np.full((20, 320), z_far)
    depth[:, 200:260] = z_near
    occluded, outside = stereo_shadow_mask(depth, F, baseline)
    width = F * baseline * (1 / z_near - 1 / z_far)
    counts = occluded.sum(axis=1)
    assert (counts == counts[0]).all() and abs(counts[0] - width) <= 1.0
    cols = np.flatnonzero(occluded[0])
    assert cols.max() == 199 and (np.diff(cols) == 1).all()  # one band, just left of the near object
    assert abs(outside[0].sum() - F * baseline / z_far) <= 1.0  # the band at the image's left edge
    assert np.flatnonzero(outside[0]).min() == 0
    assert not stereo_shadow_mask(depth, F, baseline, left_band=False)[1].any()


def test_stereo_shadows_in_the_depth_image():
    depth = np.full((10, 200), 0.4, np.float32)
    depth[:, 120:150] = 0.3
    out, drawn = apply_depth_realism(depth, F, "d405", RealismOptions(stereo_shadows=True), np.random.default_rng(0))
    rec = drawn["stereo_shadows"]
    assert (out == 0).sum() == rec["occluded_pixels"] + rec["left_band_pixels"]
    assert rec["occluded_pixels"] == 10 * 5 and rec["baseline_m"] == B  # floor(5.73) per row
    assert (out[:, 120:] > 0).all()  # the near object itself keeps its depth


def test_stereo_shadows_of_a_flat_or_tilted_plane_are_only_the_left_band():
    u = np.arange(200)
    tilted = np.tile(0.4 + 0.0005 * u, (8, 1))
    occluded, outside = stereo_shadow_mask(tilted, F, B)
    assert not occluded.any() and outside.any()


# --- RGB --------------------------------------------------------------------------------------

@pytest.mark.parametrize("level", [40, 128, 220])
def test_rgb_noise_variance_on_a_flat_grey_image(level):
    rgb = np.full((256, 256, 3), level, np.uint8)
    options = RealismOptions(rgb_noise=True)
    out, drawn = apply_rgb_realism(rgb, options, np.random.default_rng(level))
    expected = options.rgb_noise_gain * level + options.rgb_read_noise_dn**2 + 1 / 12  # + rounding
    assert abs(out.astype(np.float64).var() / expected - 1.0) < 0.03
    assert abs(out.mean() - level) < 0.05
    assert drawn["rgb_noise"]["gain"] == 0.1 and drawn["rgb_noise"]["read_noise_dn"] == 2.0


def test_rgb_noise_is_clipped_to_uint8():
    out, _ = apply_rgb_realism(np.full((64, 64, 3), 254, np.uint8), RealismOptions(rgb_noise=True),
                               np.random.default_rng(0))
    assert out.dtype == np.uint8 and out.max() == 255


def _high_frequency_energy(img):
    return float((cv2.Laplacian(img.astype(np.float64), cv2.CV_64F) ** 2).mean())


def test_blur_reduces_high_frequency_energy_more_with_larger_sigma():
    rgb = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    options = RealismOptions(rgb_blur=True, blur_sigma_max_px=2.0)
    results = [apply_rgb_realism(rgb, options, np.random.default_rng(s)) for s in range(6)]
    sigmas = [d["rgb_blur"]["sigma_px"] for _, d in results]
    energies = [_high_frequency_energy(img) for img, _ in results]
    assert all(0 <= s <= 2.0 for s in sigmas) and max(sigmas) > 1.0
    base = _high_frequency_energy(rgb)
    for s, e in zip(sigmas, energies, strict=True):
        assert e < base if s > 0.2 else e <= base * 1.01
    order = np.argsort(sigmas)
    assert all(np.diff(np.asarray(energies)[order]) <= 1e-9)


def test_exposure_scales_the_mean_by_the_recorded_gain():
    rgb = np.full((32, 32, 3), 100, np.uint8)
    gains = []
    for seed in range(8):
        out, drawn = apply_rgb_realism(rgb, RealismOptions(exposure=True), np.random.default_rng(seed))
        gain = drawn["exposure"]["gain"]
        assert 2**-0.5 <= gain <= 2**0.5 and gain == pytest.approx(2 ** drawn["exposure"]["stops"])
        assert abs(out.mean() - 100 * gain) <= 0.5  # rounding only: no pixel saturates
        gains.append(gain)
    assert min(gains) < 1 < max(gains)


def test_exposure_saturates_at_255():
    out, drawn = apply_rgb_realism(np.full((8, 8, 3), 250, np.uint8),
                                   RealismOptions(exposure=True, exposure_stops=1.0), np.random.default_rng(1))
    if drawn["exposure"]["gain"] > 255 / 250:
        assert (out == 255).all() and drawn["exposure"]["saturated_fraction"] == 1.0


# --- seeding -----------------------------------------------------------------------------------

ALL_ON = RealismOptions(**{name: True for name in CAMERA_MODEL_SWITCHES}, depth_noise=True, edge_holes=True)


def test_all_effects_are_seeded():
    depth, rgb = _bed(), np.random.default_rng(0).integers(0, 256, (96, 128, 3), dtype=np.uint8)

    def run(seed):
        rng = np.random.default_rng(seed)
        d, dd = apply_depth_realism(depth, F, "d405", ALL_ON, rng)
        c, dc = apply_rgb_realism(rgb, ALL_ON, rng)
        return d, c, {**dd, **dc}

    a, b, c = run(7), run(7), run(8)
    assert a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes() and a[2] == b[2]
    assert a[0].tobytes() != c[0].tobytes() and a[1].tobytes() != c[1].tobytes()
    assert set(a[2]) == {"correlated_noise", "disparity_quantisation", "flying_pixels", "stereo_shadows",
                         "rgb_noise", "rgb_blur", "exposure"}


def test_rendered_scene_records_every_effect():
    cfg = SceneConfig().replace(camera__width=160, camera__height=120, placement__num_mushrooms=8)
    scene = generate_scene(cfg, 2)
    options = DatasetOptions(realism=dataclasses.replace(ALL_ON, lighting=True, soil=True, camera_jitter=True))
    with SceneRenderer(120, 160) as r:
        base = r.render(scene, amodal=False)
        a = r.render(scene, options, realism_rng(0, 2), amodal=False)
        b = r.render(scene, options, realism_rng(0, 2), amodal=False)
    assert set(a.realism) == {"lighting", "soil", "camera", "correlated_noise", "disparity_quantisation",
                              "flying_pixels", "stereo_shadows", "rgb_noise", "rgb_blur", "exposure"}
    assert a.realism == b.realism and np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    assert a.realism["stereo_shadows"]["left_band_pixels"] > 0  # about f B / z = 8 px of each row
    assert a.rgb.dtype == np.uint8 and not np.array_equal(a.rgb, base.rgb)
    assert (a.depth == 0).sum() > (base.depth == 0).sum()
    from generator.dataset.writer import dumps
    assert dumps(a.realism)  # JSON-serialisable, as scene.json needs


# --- validation and the command line ---------------------------------------------------------

_WRONG_TYPE = st.one_of(st.booleans(), st.none(), st.text(max_size=5), st.lists(st.integers(), max_size=3))
_NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])


def _bad_number(lo, hi, *, lo_open=False):
    return st.one_of(_WRONG_TYPE, _NON_FINITE,
                     st.floats(max_value=lo, exclude_max=not lo_open, allow_nan=False, allow_infinity=False),
                     st.floats(min_value=hi, exclude_min=True, allow_nan=False, allow_infinity=False))


BAD_VALUES = {
    "matching_window_px": st.one_of(_WRONG_TYPE, _NON_FINITE, st.floats(allow_nan=False, allow_infinity=False),
                                    st.integers(max_value=0), st.integers(min_value=64)),
    "disparity_step_px": _bad_number(0, 1, lo_open=True),
    "flying_pixel_probability": _bad_number(0, 1),
    "rgb_noise_gain": _bad_number(0, 16), "rgb_read_noise_dn": _bad_number(0, 64),
    "blur_sigma_max_px": _bad_number(0, 10), "exposure_stops": _bad_number(0, 4),
}


def test_every_new_number_has_bad_values():
    numbers = {name for name in CAMERA_MODEL_FIELDS if not isinstance(getattr(RealismOptions(), name), bool)}
    assert numbers == set(BAD_VALUES)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(BAD_VALUES)).flatmap(lambda f: st.tuples(st.just(f), BAD_VALUES[f])))
def test_bad_camera_model_values_raise_naming_the_field(entry):
    name, value = entry
    with pytest.raises(ConfigError) as info:
        DatasetOptions.from_dict({"realism": {name: value}})
    assert info.value.field == f"realism.{name}" and f"realism.{name}" in str(info.value)


def test_cli_flags_and_realism_turn_the_effects_on(monkeypatch, tmp_path):
    import generator.dataset.runner as runner
    from generator.dataset.cli import main

    seen = []

    def fake_generate(out, cfg, num_scenes, seed, *, options, **kwargs):
        seen.append(options.realism)
        return {"scenes": [], "splits": {"train": [], "val": [], "test": []}}

    monkeypatch.setattr(runner, "generate_dataset", fake_generate)
    switches = [f.name for f in dataclasses.fields(RealismOptions) if f.type in (bool, "bool")
                and f.name != "stereo_shadows_left_band"]
    assert main(["generate", "--out", str(tmp_path / "o"), "--num-scenes", "1", "--realism", "--no-progress"]) == 0
    assert all(getattr(seen[-1], name) for name in switches)
    for name in CAMERA_MODEL_SWITCHES:
        flag = "--" + name.replace("_", "-")
        assert main(["generate", "--out", str(tmp_path / "o"), "--num-scenes", "1", flag, "--no-progress"]) == 0
        assert [n for n in switches if getattr(seen[-1], n)] == [name]
