"""RGB-D crops around a mask: the ray frame, the channels, and what is refused."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from perception.errors import NoEstimate
from perception.pose.depth_crops import CROP_CHANNELS, CROP_SIZE, crop_around_mask, ray_rotation

FX = FY = 382.0
CX, CY = 319.5, 239.5


@given(st.floats(-2, 2), st.floats(-2, 2), st.floats(0.05, 3))
def test_the_ray_rotation_is_a_rotation_taking_the_ray_onto_the_optical_axis(x: float, y: float, z: float) -> None:
    ray = np.array([x, y, z])
    q = ray_rotation(ray)
    assert np.allclose(q @ q.T, np.eye(3), atol=1e-9) and np.linalg.det(q) == pytest.approx(1.0)
    assert np.allclose(q @ (ray / np.linalg.norm(ray)), [0.0, 0.0, 1.0], atol=1e-9)


def test_the_ray_rotation_of_the_optical_axis_and_its_opposite() -> None:
    assert np.array_equal(ray_rotation(np.array([0.0, 0.0, 2.0])), np.eye(3))
    q = ray_rotation(np.array([0.0, 0.0, -1.0]))
    assert np.allclose(q @ [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]) and np.linalg.det(q) == pytest.approx(1.0)


def _disc_scene(centre=(400, 300), radius=20, depth_m=0.4, step_m=0.0):
    """A disc-shaped mask at ``depth_m`` on a floor 30 mm deeper; the disc's right half is
    ``step_m`` nearer."""
    v, u = np.mgrid[:480, :640]
    mask = (u - centre[0]) ** 2 + (v - centre[1]) ** 2 <= radius**2
    depth = np.full((480, 640), depth_m + 0.03, np.float32)
    depth[mask] = depth_m
    depth[mask & (u > centre[0])] -= step_m
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[mask] = 200
    return rgb, depth, mask


def test_a_crop_holds_the_mask_centred_and_depth_in_window_widths() -> None:
    rgb, depth, mask = _disc_scene(step_m=0.004)
    crop = crop_around_mask(rgb, depth, mask, FX, FY, CX, CY)
    image = crop.image
    assert image.shape == (CROP_CHANNELS, CROP_SIZE, CROP_SIZE) and image.dtype == np.float32
    inside = image[0] > 0
    rows, cols = np.nonzero(inside)
    assert abs(rows.mean() - (CROP_SIZE - 1) / 2) < 1 and abs(cols.mean() - (CROP_SIZE - 1) / 2) < 1
    # Window: 1.3 x 41 px + 4 px = 57.3 px; at the median depth (the far half, which has the
    # centre column: 0.4 m) that is 57.3 * 0.4 / 382 m wide.
    width_m = (1.3 * 41 + 4) * 0.4 / FX
    columns = np.arange(CROP_SIZE)[None, :]
    near_half = image[1][inside & (columns > CROP_SIZE / 2 + 2)]
    far_half = image[1][inside & (columns < CROP_SIZE / 2 - 2)]
    assert np.allclose(far_half, 0.0, atol=1e-6)
    assert np.allclose(near_half, -0.004 / width_m, rtol=1e-4)
    floor = image[1][~inside & (image[2] > 0)]
    assert np.allclose(floor, 0.03 / width_m, rtol=1e-4)
    assert np.array_equal(image[4], image[1] * image[0])
    assert np.median(image[3][inside]) == pytest.approx(200 / 255 - 0.5, abs=1e-6)  # grey, bilinear at the rim


def test_the_ray_frame_is_the_ray_through_the_window_centre() -> None:
    rgb, depth, mask = _disc_scene(centre=(500, 100))
    crop = crop_around_mask(rgb, depth, mask, FX, FY, CX, CY)
    ray = np.array([(500 - CX) / FX, (100 - CY) / FY, 1.0])
    assert np.allclose(crop.ray_from_camera @ (ray / np.linalg.norm(ray)), [0, 0, 1], atol=1e-6)


def test_a_mask_without_enough_valid_depth_gives_no_crop() -> None:
    rgb, depth, mask = _disc_scene()
    depth[mask] = 0.0
    depth[np.nonzero(mask)[0][:5], np.nonzero(mask)[1][:5]] = 0.4
    with pytest.raises(NoEstimate, match="valid depth"):
        crop_around_mask(rgb, depth, mask, FX, FY, CX, CY)
