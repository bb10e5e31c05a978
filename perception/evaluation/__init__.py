"""Measurements of the perception stages: the two-stage pipeline on held-out scenes, with
intervals that resample whole scenes. The point network's own evaluations (held-out views, the
SMS3D ablations) live with it in :mod:`perception.baselines.point_transformer`."""
