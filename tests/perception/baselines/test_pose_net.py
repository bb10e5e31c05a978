"""Backbones, PoseNet heads, configs and checkpoints."""

from __future__ import annotations

import pytest
import torch

from perception.baselines.point_transformer.backbones import BACKBONES
from perception.baselines.point_transformer.pose_net import (
    PoseNet,
    PoseNetConfig,
    load_backbone,
    load_checkpoint,
    load_weights,
    save_checkpoint,
)
from perception.choices import HEAD_NAMES
from perception.errors import CheckpointMismatchError, PerceptionConfigError


@pytest.mark.parametrize("name", sorted(BACKBONES))
def test_backbone_is_invariant_to_point_order(name: str) -> None:
    torch.manual_seed(0)
    net = PoseNet(backbone=name, num_points=256).eval()
    x = torch.rand(2, 256, 3) * 2 - 1
    perm = torch.randperm(256)
    with torch.no_grad():
        a, b = net(x), net(x[:, perm])
    assert torch.allclose(a, b, atol=1e-4)


@pytest.mark.parametrize("head", HEAD_NAMES)
@pytest.mark.parametrize("use_rgb", [False, True])
def test_heads_output_rotations(head: str, use_rgb: bool) -> None:
    net = PoseNet(backbone="pointnet", head=head, use_rgb=use_rgb, num_points=64).eval()
    x = torch.rand(3, 64, 6 if use_rgb else 3)
    with torch.no_grad():
        R = net(x)
    assert R.shape == (3, 3, 3)
    assert torch.allclose(R.transpose(1, 2) @ R, torch.eye(3).expand(3, 3, 3), atol=1e-4)
    assert torch.allclose(torch.det(R), torch.ones(3), atol=1e-4)
    with pytest.raises(ValueError, match="use_rgb"):
        net(torch.rand(1, 64, 3 if use_rgb else 6))


def test_point_transformer_gradients_flow() -> None:
    net = PoseNet(num_points=128)
    R = net(torch.rand(2, 128, 3))
    R.sum().backward()
    grads = [p.grad for p in net.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"backbone": "resnet"}, "backbone"), ({"head": "7d"}, "head"), ({"num_points": 8}, "num_points"), ({"use_rgb": 1}, "use_rgb"),
     ({"depth_smoothing_px": -1.0}, "depth_smoothing_px"), ({"depth_smoothing_px": float("nan")}, "depth_smoothing_px"),
     ({"depth_smoothing_px": 25}, "depth_smoothing_px"), ({"depth_smoothing_px": True}, "depth_smoothing_px")],
)
def test_config_errors_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(PerceptionConfigError) as info:
        PoseNetConfig(**kwargs)
    assert info.value.field == field


def test_checkpoint_round_trip_and_mismatch(tmp_path) -> None:
    torch.manual_seed(0)
    net = PoseNet(backbone="pointnet2", head="quat", num_points=128).eval()
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, net, {"note": "x"})
    loaded, extra = load_checkpoint(path)
    assert loaded.config == net.config and extra == {"note": "x"}
    x = torch.rand(2, 128, 3)
    with torch.no_grad():
        assert torch.allclose(loaded(x), net(x))
    with pytest.raises(CheckpointMismatchError) as info:
        load_checkpoint(path, PoseNetConfig(backbone="pointnet2", head="6d", num_points=128))
    assert set(info.value.mismatches) == {"head"}
    assert "head" in str(info.value) and "'quat'" in str(info.value)
    assert not list(tmp_path.glob("*.tmp"))  # atomic write left no temporary file


def test_a_checkpoint_saved_before_depth_smoothing_existed_reads_raw_depth(tmp_path) -> None:
    net = PoseNet(backbone="pointnet", num_points=64)
    path = tmp_path / "old.pt"
    save_checkpoint(path, net)
    payload = torch.load(path, weights_only=True)
    del payload["config"]["depth_smoothing_px"]  # as written by earlier versions
    torch.save(payload, path)
    assert load_checkpoint(path)[0].config.depth_smoothing_px == 0.0


def test_load_weights_lets_the_input_fields_change_but_not_the_shape(tmp_path) -> None:
    torch.manual_seed(0)
    trained = PoseNet(backbone="pointnet", num_points=64)
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, trained)
    smoothed = PoseNet(backbone="pointnet", num_points=64, depth_smoothing_px=4.0)
    load_weights(smoothed, path)
    assert smoothed.config.depth_smoothing_px == 4.0
    assert all(torch.equal(v, trained.state_dict()[k]) for k, v in smoothed.state_dict().items())
    with pytest.raises(CheckpointMismatchError) as info:
        load_weights(PoseNet(backbone="pointnet", num_points=64, hidden=32), path)
    assert set(info.value.mismatches) == {"hidden"}


@pytest.mark.parametrize("name", ["point_transformer", "pointnet"])
def test_an_xyz_network_starts_an_rgb_one_that_predicts_what_it_did(tmp_path, name: str) -> None:
    torch.manual_seed(0)
    xyz_net = PoseNet(backbone=name, num_points=64).eval()
    path = tmp_path / "xyz.pt"
    save_checkpoint(path, xyz_net)
    rgb_net = PoseNet(backbone=name, num_points=64, use_rgb=True).eval()
    load_weights(rgb_net, path)
    points = torch.rand(3, 64, 3) * 2 - 1
    with torch.no_grad():
        before = xyz_net(points)
        for colours in (torch.zeros(3, 64, 3), torch.rand(3, 64, 3)):
            assert torch.allclose(rgb_net(torch.cat([points, colours], -1)), before, atol=1e-6)
    # The colour weights are real parameters that training can move.
    weight = dict(rgb_net.named_parameters())[f"backbone.{rgb_net.backbone.input_weight}"]
    assert weight.shape[1] == 6 and weight.requires_grad and torch.all(weight[:, 3:] == 0)


def test_an_rgb_network_cannot_start_an_xyz_one_nor_pointnet2_widen(tmp_path) -> None:
    torch.manual_seed(0)
    path = tmp_path / "rgb.pt"
    save_checkpoint(path, PoseNet(backbone="pointnet", num_points=64, use_rgb=True))
    with pytest.raises(CheckpointMismatchError) as info:
        load_weights(PoseNet(backbone="pointnet", num_points=64), path)
    assert set(info.value.mismatches) == {"use_rgb"}
    save_checkpoint(path, PoseNet(backbone="pointnet2", num_points=64))
    with pytest.raises(CheckpointMismatchError) as info:
        load_weights(PoseNet(backbone="pointnet2", num_points=64, use_rgb=True), path)
    assert set(info.value.mismatches) == {"use_rgb"}


def test_load_backbone_switches_the_head_and_names_mismatches(tmp_path) -> None:
    torch.manual_seed(0)
    trained = PoseNet(backbone="pointnet", head="6d", num_points=64)
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, trained)
    net = PoseNet(backbone="pointnet", head="6d_stem", num_points=128)
    load_backbone(net, path)
    x = torch.rand(2, 128, 3)
    with torch.no_grad():
        assert torch.equal(net.backbone(x), trained.backbone(x))
        assert torch.equal(net.head[0].weight, trained.head[0].weight)
        # The output layer starts at the upright prior: R = diag(1, -1, -1) for every input.
        net.head[-1].weight.zero_()
        assert torch.allclose(net(x), torch.diag(torch.tensor([1.0, -1.0, -1.0])).expand(2, 3, 3), atol=1e-6)
    with pytest.raises(CheckpointMismatchError) as info:
        load_backbone(PoseNet(backbone="pointnet2", head="6d", num_points=64), path)
    assert set(info.value.mismatches) == {"backbone"}
