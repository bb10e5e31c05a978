"""Stage 2, pose estimation: per-mushroom point clouds to rotations whose third column is the
stem axis (networks, rotation heads, training data, training loops, inference)."""
