"""Rotation representations, conversions and rotation losses in batched torch.

Rotation matrices are the canonical form (``(..., 3, 3)``, columns are the rotated frame's axes);
every other representation converts to and from them here. All functions accept any leading batch
shape and are differentiable unless stated otherwise. The generic conversions (Gram–Schmidt, SVD
projection, quaternions, Euler angles) are roma's (Brégier, 2021, "Deep regression on manifolds:
a 3D rotation case study"); this module fixes the conventions, and keeps the stem-first 6D head and
the losses, which roma does not have. ``ROTATION_HEADS`` is the one table of the heads.

Conventions:
- 6D: the first two columns of ``R`` stacked as ``(..., 6) = [c0, c1]``; decoded by Gram–Schmidt
  (Zhou et al., CVPR 2019, "On the Continuity of Rotation Representations in Neural Networks").
- 6D stem-first: ``[c2, c0]``, the stem axis first, decoded by the same Gram–Schmidt.
- 9D: any ``(..., 9)`` row-major 3x3 matrix, projected to the nearest rotation by SVD with
  ``det = +1`` (Levinson et al. 2020).
- Quaternion: ``(w, x, y, z)``, scalar first; decoding normalises.
- Euler: ``(roll, pitch, yaw)`` about x, y, z with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
- The stem axis of a mushroom is its local +z, i.e. the third column ``R[..., :, 2]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import roma
import torch

from perception.choices import ROTATION_LOSSES

RotationLoss = Literal["geodesic", "axis", "geodesic+axis"]

_DEFAULT_EPS = 1e-6


def _check_last(x: torch.Tensor, shape: tuple[int, ...], name: str) -> None:
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if tuple(x.shape[x.dim() - len(shape) :]) != shape or x.dim() < len(shape):
        raise ValueError(f"{name}: expected shape (..., {', '.join(map(str, shape))}), got {tuple(x.shape)}")


# --------------------------------------------------------------------------- 6D (Gram–Schmidt)
def _gram_schmidt(a1: torch.Tensor, a2: torch.Tensor) -> torch.Tensor:
    """Columns ``(b1, b2, b1 × b2)``, orthonormal and right-handed, with ``b1 ∥ a1`` and ``b2`` in
    ``span(a1, a2)`` (roma's ``special_gramschmidt``; norms clamped at ``_DEFAULT_EPS``)."""
    return roma.special_gramschmidt(torch.stack((a1, a2), dim=-1), epsilon=_DEFAULT_EPS)


def rotation_6d_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """Decode ``(..., 6)`` = two 3-vectors into a rotation by Gram–Schmidt.

    ``b1 = a1/|a1|``, ``b2 = normalise(a2 - (b1·a2) b1)``, ``b3 = b1 × b2``; the columns of the
    result are ``[b1, b2, b3]`` so that ``matrix_to_rotation_6d`` inverts it exactly.
    """
    _check_last(d6, (6,), "d6")
    return _gram_schmidt(d6[..., :3], d6[..., 3:])


def matrix_to_rotation_6d(R: torch.Tensor) -> torch.Tensor:
    """The first two columns of ``R`` as ``(..., 6)``."""
    _check_last(R, (3, 3), "R")
    return torch.cat((R[..., :, 0], R[..., :, 1]), dim=-1)


def rotation_6d_stem_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """Decode ``(..., 6)`` = ``[stem axis, x axis]`` by Gram–Schmidt with the stem axis first.

    ``z = a1/|a1|``, ``x = normalise(a2 - (z·a2) z)``, ``y = z × x``; columns ``[x, y, z]``.
    The same 6D representation as :func:`rotation_6d_to_matrix` with the third column taken
    first, so the stem axis is a normalised output of its own: yaw about the stem, which a
    near-round cap hides, only moves ``x`` and ``y``. In the plain 6D decoding the stem axis is
    the cross product of the two yaw-dependent columns.
    """
    _check_last(d6, (6,), "d6")
    zxy = _gram_schmidt(d6[..., :3], d6[..., 3:])
    return zxy[..., [1, 2, 0]]


def matrix_to_rotation_6d_stem(R: torch.Tensor) -> torch.Tensor:
    """The stem axis (third column) and the first column of ``R`` as ``(..., 6)``."""
    _check_last(R, (3, 3), "R")
    return torch.cat((R[..., :, 2], R[..., :, 0]), dim=-1)


# --------------------------------------------------------------------------- 9D (SVD)
def rotation_9d_to_matrix(d9: torch.Tensor) -> torch.Tensor:
    """Project ``(..., 9)`` (row-major 3x3) onto SO(3) by SVD, forcing ``det = +1`` (roma's
    ``special_procrustes``)."""
    _check_last(d9, (9,), "d9")
    return roma.special_procrustes(d9.reshape(*d9.shape[:-1], 3, 3))


def matrix_to_rotation_9d(R: torch.Tensor) -> torch.Tensor:
    """Flatten ``R`` row-major to ``(..., 9)``."""
    _check_last(R, (3, 3), "R")
    return R.reshape(*R.shape[:-2], 9)


# --------------------------------------------------------------------------- quaternion
def quaternion_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """``(w, x, y, z)`` (normalised here) to a rotation matrix (roma works scalar-last)."""
    _check_last(q, (4,), "q")
    q = torch.nn.functional.normalize(q, dim=-1, eps=_DEFAULT_EPS)
    return roma.unitquat_to_rotmat(roma.quat_wxyz_to_xyzw(q))


def matrix_to_quaternion(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrix to a unit quaternion ``(w, x, y, z)`` with ``w >= 0``."""
    _check_last(R, (3, 3), "R")
    q = roma.quat_xyzw_to_wxyz(roma.rotmat_to_unitquat(R))
    return torch.where(q[..., :1] < 0, -q, q)


# --------------------------------------------------------------------------- Euler xyz
def euler_to_matrix(e: torch.Tensor) -> torch.Tensor:
    """``(roll, pitch, yaw)`` to ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (roma's extrinsic "xyz")."""
    _check_last(e, (3,), "euler")
    return roma.euler_to_rotmat("xyz", e)


def matrix_to_euler(R: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`euler_to_matrix`; pitch in ``[-pi/2, pi/2]``.

    Not differentiable-safe at gimbal lock (``|pitch| = pi/2``), where roll is set to zero.
    """
    _check_last(R, (3, 3), "R")
    sp = torch.clamp(-R[..., 2, 0], -1.0, 1.0)
    pitch = torch.asin(sp)
    cp = torch.sqrt(torch.clamp(R[..., 0, 0] ** 2 + R[..., 1, 0] ** 2, min=0.0))
    regular = cp > 1e-6
    roll = torch.where(regular, torch.atan2(R[..., 2, 1], R[..., 2, 2]), torch.zeros_like(sp))
    yaw = torch.where(
        regular,
        torch.atan2(R[..., 1, 0], R[..., 0, 0]),
        torch.atan2(-R[..., 0, 1], R[..., 1, 1]),
    )
    return torch.stack((roll, pitch, yaw), dim=-1)


# --------------------------------------------------------------------------- the heads
@dataclass(frozen=True)
class RotationHead:
    """One rotation head of the pose network: the size of its raw output, how that output
    decodes to a rotation and a rotation encodes to it, and the raw output of an upright
    mushroom seen from above (stem axis along the camera's -z), with which the head's bias starts."""

    dim: int
    to_matrix: Callable[[torch.Tensor], torch.Tensor]
    from_matrix: Callable[[torch.Tensor], torch.Tensor]
    upright: tuple[float, ...]


#: Every head, by the name a ``PoseNetConfig`` stores (``perception.choices.HEAD_NAMES`` lists the
#: same names without importing torch, for ``sms3d --help``).
ROTATION_HEADS: dict[str, RotationHead] = {
    "6d": RotationHead(6, rotation_6d_to_matrix, matrix_to_rotation_6d, (1.0, 0, 0, 0, -1.0, 0)),
    "6d_stem": RotationHead(6, rotation_6d_stem_to_matrix, matrix_to_rotation_6d_stem, (0.0, 0, -1.0, 1.0, 0, 0)),
    "9d": RotationHead(9, rotation_9d_to_matrix, matrix_to_rotation_9d, (1.0, 0, 0, 0, -1.0, 0, 0, 0, -1.0)),
    "quat": RotationHead(4, quaternion_to_matrix, matrix_to_quaternion, (0.0, 1.0, 0, 0)),  # pi about x
    "euler": RotationHead(3, euler_to_matrix, matrix_to_euler, (math.pi, 0.0, 0.0)),  # roll = pi
}


# --------------------------------------------------------------------------- errors and losses
def geodesic_angle(R1: torch.Tensor, R2: torch.Tensor, eps: float = 1e-7) -> torch.Tensor:
    """Angle (rad) of ``R1ᵀ R2``: ``arccos((tr - 1)/2)``, the argument clamped to
    ``[-1 + eps, 1 - eps]`` so the gradient stays finite at 0 and pi."""
    _check_last(R1, (3, 3), "R1")
    _check_last(R2, (3, 3), "R2")
    tr = (R1 * R2).sum(dim=(-2, -1))  # trace(R1ᵀ R2)
    return torch.acos(torch.clamp((tr - 1.0) * 0.5, -1.0 + eps, 1.0 - eps))


def axis_angle_error(R1: torch.Tensor, R2: torch.Tensor, eps: float = 1e-7) -> torch.Tensor:
    """Angle (rad) between the stem axes (third columns) of ``R1`` and ``R2``.

    Invariant to yaw about the stem: the symmetry-aware error for an axisymmetric mushroom.
    """
    _check_last(R1, (3, 3), "R1")
    _check_last(R2, (3, 3), "R2")
    a = torch.nn.functional.normalize(R1[..., :, 2], dim=-1)
    b = torch.nn.functional.normalize(R2[..., :, 2], dim=-1)
    return torch.acos(torch.clamp((a * b).sum(-1), -1.0 + eps, 1.0 - eps))


def rotation_loss(pred: torch.Tensor, target: torch.Tensor, kind: RotationLoss = "geodesic") -> torch.Tensor:
    """Mean rotation loss in radians.

    - ``"geodesic"``: full SO(3) angle — penalises yaw about the stem as well.
    - ``"axis"``: stem-axis angle only — yaw-invariant (symmetry-aware) loss.
    - ``"geodesic+axis"``: their sum; keeps yaw supervision where it is observable while
      weighting the axis, which a picker needs, twice.
    """
    if kind == "geodesic":
        return geodesic_angle(pred, target).mean()
    if kind == "axis":
        return axis_angle_error(pred, target).mean()
    if kind == "geodesic+axis":
        return geodesic_angle(pred, target).mean() + axis_angle_error(pred, target).mean()
    raise ValueError(f"loss: expected one of {ROTATION_LOSSES}, got {kind!r}")


def random_rotations(n: int, generator: torch.Generator | None = None, dtype=torch.float32) -> torch.Tensor:
    """``n`` rotations drawn uniformly (Haar) from SO(3) via normalised Gaussian quaternions."""
    q = torch.randn(n, 4, generator=generator, dtype=torch.float64)
    return quaternion_to_matrix(q).to(dtype)


#: Mean geodesic error of a uniformly random guess: ``pi/2 + 2/pi`` rad ≈ 126.5°.
CHANCE_GEODESIC_DEG: float = math.degrees(math.pi / 2 + 2 / math.pi)
#: Mean angle between two uniformly random unit vectors: 90°.
CHANCE_AXIS_DEG: float = 90.0
