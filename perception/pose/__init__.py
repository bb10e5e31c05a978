"""Stage 2, pose estimation: per-mushroom RGB-D crops to stem axes (``axis_cnn``,
``depth_crops``, ``train_axis_cnn``, ``widen``), and the rotation representations and losses
(``rotations``). The paper's point network is a baseline: :mod:`perception.baselines.point_transformer`."""
