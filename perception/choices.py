"""The perception networks' named options, without torch.

``sms3d --help`` lists these as argparse choices; they live here, not in
:mod:`perception.baselines.point_transformer.pose_net` or :mod:`perception.baselines.maskrcnn.model`
(which import them from this module), so that building the CLI's parser does not load torch
and torchvision.
"""

from __future__ import annotations

#: Names of the pose network's rotation heads: the keys of
#: ``perception.pose.rotations.ROTATION_HEADS``, which defines them (a test keeps the two equal).
HEAD_NAMES: tuple[str, ...] = ("6d", "6d_stem", "9d", "quat", "euler")

#: Point-cloud backbones: the keys of ``perception.baselines.point_transformer.backbones.BACKBONES`` (a test keeps them equal).
BACKBONE_NAMES: tuple[str, ...] = ("point_transformer", "pointnet", "pointnet2")

#: Rotation losses of the pose network (``perception.pose.rotations.rotation_loss``).
ROTATION_LOSSES: tuple[str, ...] = ("geodesic", "axis", "geodesic+axis")

#: Losses of the axis CNN (``perception.pose.train_axis_cnn.axis_loss``).
AXIS_LOSSES: tuple[str, ...] = ("cosine", "angle")

#: Mask R-CNN configurations (see :mod:`perception.baselines.maskrcnn.model`).
ARCHITECTURES = ("mobilenet_v3_fpn", "resnet50_fpn_v2")

#: Categories a detector can be trained on, with the dataset's COCO category ids.
CATEGORIES = {"mushroom": 1, "mushroom_cap": 2}
