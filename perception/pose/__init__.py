"""Stage 2, pose estimation: per-mushroom RGB-D crops to stem axes (``axis_cnn``,
``depth_crops``, ``train_axis_cnn``), and per-mushroom point clouds to rotations whose third
column is the stem axis (networks, rotation heads, training data, training loops, inference)."""
