"""Measurements of the perception stages: the two-stage pipeline on held-out scenes, the pose
network on held-out sets, and the SMS3D ablations."""
