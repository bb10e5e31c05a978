import math

import pytest

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
