"""RGB-D image crops around one mushroom's mask: the input of the axis CNN (``axis_cnn``).

A crop is a square window around the mask's bounding box (``CROP_MARGIN`` times its larger
side, plus ``CROP_PAD_PX``), resampled to ``CROP_SIZE`` x ``CROP_SIZE`` pixels, with channels:

=====  ====================================================================================
0      the mask (0 / 1)
1      depth relative to the mask's median depth, in units of the window's width in metres,
       clipped to [-1, 1]; 0 where depth is invalid
2      depth validity (0 / 1)
3      grey level of the RGB image, in [-0.5, 0.5]
4      channel 1 inside the mask, 0 outside
=====  ====================================================================================

Depth and mask are sampled nearest-neighbour (a stereo camera's invalid zeros and the mask's
edge are not blurred), grey bilinearly. Dividing depth by the window's width makes the crop of a
mushroom the same at any size or distance, as the point network's unit-sphere normalisation does.

Directions are expressed in the crop's *ray frame*: the camera frame turned so that the ray
through the window's centre is the optical axis (``ray_rotation``). A crop far from the image
centre then looks at its mushroom as a crop at the centre would, up to the perspective inside
the window.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from generator.geometry import axis_angle_matrix
from perception.errors import NoEstimate

#: Crop side in pixels.
CROP_SIZE = 48
#: Window side as a multiple of the mask's larger bounding-box side (room for the rim and soil).
CROP_MARGIN = 1.3
#: Pixels added to the window's side (small masks still show their surroundings).
CROP_PAD_PX = 4.0
#: Channels of a crop (see the module doc).
CROP_CHANNELS = 5
#: Fewest valid depth pixels under a mask for a crop.
MIN_VALID_PIXELS = 20


@dataclass(frozen=True)
class DepthCrop:
    """One mushroom's crop: ``image (CROP_CHANNELS, CROP_SIZE, CROP_SIZE)`` float32 and
    ``ray_from_camera (3, 3)``, the rotation from the camera frame into the crop's ray frame."""

    image: np.ndarray
    ray_from_camera: np.ndarray


def ray_rotation(ray: np.ndarray) -> np.ndarray:
    """The smallest rotation ``(3, 3)`` that takes the direction ``ray (3,)`` onto the optical
    axis ``(0, 0, 1)``: about ``ray x z`` by the angle between them."""
    ray = np.asarray(ray, dtype=np.float64)
    ray = ray / np.linalg.norm(ray)
    axis = np.cross(ray, [0.0, 0.0, 1.0])
    sine = float(np.linalg.norm(axis))
    if sine < 1e-12:
        return np.eye(3) if ray[2] > 0 else np.diag([1.0, -1.0, -1.0])
    # atan2 of sine and cosine, not arccos of the cosine: arccos loses half the digits near 0
    return axis_angle_matrix(axis, float(np.arctan2(sine, ray[2])))


def crop_around_mask(rgb: np.ndarray, depth: np.ndarray, mask: np.ndarray, fx: float, fy: float,
                     cx: float, cy: float) -> DepthCrop:
    """The crop of ``rgb (H, W, 3)`` uint8 and metric ``depth (H, W)`` (0, NaN = invalid) around the
    boolean ``mask (H, W)``, for a pinhole camera of focal lengths and principal point in pixels.

    Raises:
        NoEstimate: fewer than ``MIN_VALID_PIXELS`` valid depth pixels under the mask.
    """
    depth = np.where(np.isfinite(depth), depth, 0.0)  # NaN / inf: invalid, like 0
    valid_mask = mask & (depth > 0)
    found = int(np.count_nonzero(valid_mask))
    if found < MIN_VALID_PIXELS:
        raise NoEstimate(found, MIN_VALID_PIXELS, "too few valid depth pixels under the mask")
    ys, xs = np.nonzero(mask)
    centre_u, centre_v = (xs.min() + xs.max()) / 2.0, (ys.min() + ys.max()) / 2.0
    side = CROP_MARGIN * max(xs.max() - xs.min() + 1, ys.max() - ys.min() + 1) + CROP_PAD_PX
    scale = side / CROP_SIZE
    half = (CROP_SIZE - 1) / 2.0
    # Crop pixel (a, b) samples the image at centre + scale * ((a, b) - half).
    image_from_crop = np.array([[scale, 0.0, centre_u - scale * half], [0.0, scale, centre_v - scale * half]])
    inverse = cv2.WARP_INVERSE_MAP
    size = (CROP_SIZE, CROP_SIZE)
    d = cv2.warpAffine(depth.astype(np.float32), image_from_crop, size, flags=cv2.INTER_NEAREST | inverse)
    m = cv2.warpAffine(mask.astype(np.uint8), image_from_crop, size, flags=cv2.INTER_NEAREST | inverse)
    grey = cv2.warpAffine(rgb[..., :3].astype(np.float32).mean(2), image_from_crop, size,
                          flags=cv2.INTER_LINEAR | inverse)
    reference = float(np.median(depth[valid_mask]))
    width_m = side * reference / fx
    valid = (d > 0).astype(np.float32)
    relative = np.clip((d - reference) / width_m, -1.0, 1.0) * valid
    m = m.astype(np.float32)
    image = np.stack([m, relative, valid, grey / 255.0 - 0.5, relative * m]).astype(np.float32)
    ray = np.array([(centre_u - cx) / fx, (centre_v - cy) / fy, 1.0])
    return DepthCrop(image, ray_rotation(ray))
