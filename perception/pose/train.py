"""Deprecated (2026-12-06), removed after 2027-06-06: moved to :mod:`perception.baselines.point_transformer.train`."""

from perception.deprecation import moved_module

moved_module(__spec__.name, "perception.baselines.point_transformer.train")
