"""The perception networks' named options, without torch.

``sms3d --help`` lists these as argparse choices; they live here, not in :mod:`perception.pose_net`
or :mod:`perception.maskrcnn` (which import them from this module), so that building the CLI's
parser does not load torch and torchvision.
"""

from __future__ import annotations

#: Rotation heads of the pose network and the size of each one's raw output.
HEAD_DIMS: dict[str, int] = {"6d": 6, "6d_stem": 6, "9d": 9, "quat": 4, "euler": 3}

#: Mask R-CNN configurations (see :mod:`perception.maskrcnn`).
ARCHITECTURES = ("mobilenet_v3_fpn", "resnet50_fpn_v2")

#: Categories a detector can be trained on, with the dataset's COCO category ids.
CATEGORIES = {"mushroom": 1, "mushroom_cap": 2}
