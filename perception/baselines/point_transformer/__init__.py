"""The Point Transformer with a 6D rotation head for stage 2 (the SMS3D paper's pose network), a
baseline: per-mushroom point clouds in the camera frame to rotations whose third column is the
stem axis.

- the network: ``pose_net`` (``PoseNet``, checkpoints), ``backbones`` (Point Transformer,
  PointNet, PointNet++), ``config`` (``PoseNetConfig``, ``TrainConfig``, without torch);
- inference: ``estimator`` (``PoseEstimator``, the shipped weights ``posenet_default.pt``);
- data and training: ``data`` (samples and their ``.npz`` format), ``synthetic_views``
  (single-mushroom renders), ``augment``, ``depth_smoothing``, ``train``, ``recipe`` (the
  settings ``sms3d train-pose`` reads from ``recipe.yml``), ``cli`` (``train-pose``,
  ``eval-pose``);
- measurements: ``metrics``, ``eval_heldout`` (held-out views and scenes), ``ablation`` (the
  paper's ablations).
"""
