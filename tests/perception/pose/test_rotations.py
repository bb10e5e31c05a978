"""Rotation representations, conversions and losses."""

from __future__ import annotations

import math

import pytest
import torch

from perception.pose import rotations as rot


@pytest.fixture
def R() -> torch.Tensor:
    return rot.random_rotations(256, torch.Generator().manual_seed(0), dtype=torch.float64)


def _assert_rotations(M: torch.Tensor) -> None:
    eye = torch.eye(3, dtype=M.dtype).expand_as(M)
    assert torch.allclose(M.transpose(-1, -2) @ M, eye, atol=1e-5)
    assert torch.allclose(torch.det(M), torch.ones(M.shape[0], dtype=M.dtype), atol=1e-5)


def test_gram_schmidt_and_svd_give_rotations() -> None:
    g = torch.Generator().manual_seed(1)
    _assert_rotations(rot.rotation_6d_to_matrix(torch.randn(500, 6, generator=g)))
    _assert_rotations(rot.rotation_6d_stem_to_matrix(torch.randn(500, 6, generator=g)))
    # Random 9D inputs include reflections (det < 0); SVD projection must still give det = +1.
    m9 = torch.randn(500, 9, generator=g)
    assert (torch.det(m9.view(-1, 3, 3)) < 0).any()
    _assert_rotations(rot.rotation_9d_to_matrix(m9))


@pytest.mark.parametrize(
    ("enc", "dec"),
    [
        (rot.matrix_to_rotation_6d, rot.rotation_6d_to_matrix),
        (rot.matrix_to_rotation_6d_stem, rot.rotation_6d_stem_to_matrix),
        (rot.matrix_to_rotation_9d, rot.rotation_9d_to_matrix),
        (rot.matrix_to_quaternion, rot.quaternion_to_matrix),
        (rot.matrix_to_euler, rot.euler_to_matrix),
    ],
)
def test_round_trip(R: torch.Tensor, enc, dec) -> None:
    assert torch.allclose(dec(enc(R)), R, atol=1e-6)


def test_stem_first_6d_keeps_the_stem_axis_when_yaw_is_unknown() -> None:
    # A network unsure of yaw outputs a shrunken, noisy second vector; the stem-first decoding
    # keeps the stem axis exactly, the plain one (axis = b1 × b2) does not.
    g = torch.Generator().manual_seed(2)
    R = rot.random_rotations(200, g, dtype=torch.float64)
    noise = 0.3 * torch.randn(200, 3, generator=g, dtype=torch.float64)
    stem = rot.rotation_6d_stem_to_matrix(torch.cat((R[:, :, 2], R[:, :, 0] + noise), -1))
    plain = rot.rotation_6d_to_matrix(torch.cat((R[:, :, 0] + noise, R[:, :, 1]), -1))
    assert torch.allclose(stem[:, :, 2], R[:, :, 2], atol=1e-12)
    assert torch.rad2deg(rot.axis_angle_error(plain, R)).mean() > 5.0


def test_euler_convention_is_rz_ry_rx() -> None:
    e = torch.tensor([0.3, -0.2, 1.1], dtype=torch.float64)
    Rx = rot.euler_to_matrix(torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64))
    Ry = rot.euler_to_matrix(torch.tensor([0.0, -0.2, 0.0], dtype=torch.float64))
    Rz = rot.euler_to_matrix(torch.tensor([0.0, 0.0, 1.1], dtype=torch.float64))
    assert torch.allclose(rot.euler_to_matrix(e), Rz @ Ry @ Rx)
    assert torch.allclose(Rx[1:, 1:], torch.tensor([[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]], dtype=torch.float64))


def test_quaternion_sign_and_identity() -> None:
    q = rot.matrix_to_quaternion(torch.eye(3).unsqueeze(0))
    assert torch.allclose(q, torch.tensor([[1.0, 0, 0, 0]]))
    # 180° about x: w = 0 branch.
    Rx = torch.diag(torch.tensor([1.0, -1.0, -1.0])).unsqueeze(0)
    assert torch.allclose(rot.quaternion_to_matrix(rot.matrix_to_quaternion(Rx)), Rx, atol=1e-6)


def test_geodesic_equals_angle_of_relative_rotation(R: torch.Tensor) -> None:
    g = torch.Generator().manual_seed(2)
    axis = torch.nn.functional.normalize(torch.randn(256, 3, generator=g, dtype=torch.float64), dim=-1)
    angle = torch.rand(256, generator=g, dtype=torch.float64) * (math.pi - 0.01)
    K = torch.zeros(256, 3, 3, dtype=torch.float64)
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - K.transpose(1, 2)
    delta = torch.linalg.matrix_exp(K * angle[:, None, None])  # rotation by `angle` about `axis`
    assert torch.allclose(rot.geodesic_angle(R, R @ delta), angle, atol=1e-5)
    # And against an independent formula: the angle from the quaternion of RᵀR̂.
    q = rot.matrix_to_quaternion(R.transpose(1, 2) @ (R @ delta))
    assert torch.allclose(2 * torch.atan2(q[:, 1:].norm(dim=-1), q[:, 0]), angle, atol=1e-5)


@pytest.mark.parametrize("angle", [0.0, math.pi])
def test_geodesic_gradient_is_finite_at_0_and_pi(angle: float) -> None:
    target = torch.eye(3, dtype=torch.float64).unsqueeze(0)
    d6 = rot.matrix_to_rotation_6d(rot.euler_to_matrix(torch.tensor([[angle, 0.0, 0.0]], dtype=torch.float64)))
    d6.requires_grad_(True)
    loss = rot.geodesic_angle(rot.rotation_6d_to_matrix(d6), target).sum()
    loss.backward()
    assert torch.isfinite(d6.grad).all()
    assert loss.item() == pytest.approx(angle, abs=1e-3)


def test_axis_error_ignores_yaw_and_sees_tilt() -> None:
    R = rot.euler_to_matrix(torch.tensor([[0.2, -0.1, 0.0]], dtype=torch.float64))
    Ryaw = rot.euler_to_matrix(torch.tensor([[0.0, 0.0, 1.3]], dtype=torch.float64))
    assert rot.axis_angle_error(R, R @ Ryaw).item() == pytest.approx(0.0, abs=1e-3)
    assert rot.geodesic_angle(R, R @ Ryaw).item() == pytest.approx(1.3, abs=1e-6)
    tilt = rot.euler_to_matrix(torch.tensor([[0.4, 0.0, 0.0]], dtype=torch.float64))
    assert rot.axis_angle_error(torch.eye(3, dtype=torch.float64)[None], tilt).item() == pytest.approx(0.4, abs=1e-6)
    assert rot.rotation_loss(R, R @ Ryaw, "axis").item() < 1e-3
    with pytest.raises(ValueError, match="loss"):
        rot.rotation_loss(R, R, "l2")  # type: ignore[arg-type]


def test_chance_levels_match_random_rotations() -> None:
    R1 = rot.random_rotations(20000, torch.Generator().manual_seed(3), dtype=torch.float64)
    R2 = rot.random_rotations(20000, torch.Generator().manual_seed(4), dtype=torch.float64)
    assert math.degrees(rot.geodesic_angle(R1, R2).mean()) == pytest.approx(rot.CHANCE_GEODESIC_DEG, abs=1.0)
    assert math.degrees(rot.axis_angle_error(R1, R2).mean()) == pytest.approx(rot.CHANCE_AXIS_DEG, abs=1.0)


def test_bad_shapes_raise() -> None:
    with pytest.raises(ValueError, match="d6"):
        rot.rotation_6d_to_matrix(torch.zeros(2, 5))
    with pytest.raises(ValueError, match="R1"):
        rot.geodesic_angle(torch.zeros(3), torch.eye(3))


def test_head_registry_is_the_one_table_of_heads() -> None:
    """The torch-free names ``sms3d --help`` offers are the registry's; each head's upright output
    decodes to a mushroom whose stem points at the camera (camera -z), and encoding inverts
    decoding."""
    from perception.choices import HEAD_NAMES

    assert HEAD_NAMES == tuple(rot.ROTATION_HEADS)
    from perception.baselines.point_transformer.backbones import BACKBONES
    from perception.choices import BACKBONE_NAMES

    assert BACKBONE_NAMES == tuple(BACKBONES)  # the same for the backbones
    R = rot.random_rotations(16, torch.Generator().manual_seed(3), dtype=torch.float64)
    for name, head in rot.ROTATION_HEADS.items():
        upright = head.to_matrix(torch.tensor(head.upright, dtype=torch.float64))
        assert torch.allclose(upright[:, 2], torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64), atol=1e-9), name
        raw = head.from_matrix(R)
        assert raw.shape == (16, head.dim), name
        assert torch.allclose(head.to_matrix(raw), R, atol=1e-6), name
