"""Typed errors raised by the perception package."""

from __future__ import annotations


class PerceptionConfigError(ValueError):
    """An invalid configuration value; ``field`` names the offending field."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field


class CheckpointMismatchError(ValueError):
    """A checkpoint whose stored configuration differs from the one asked for.

    ``mismatches`` maps each differing field to ``(stored, requested)``.
    """

    def __init__(self, path: str, mismatches: dict[str, tuple[object, object]]) -> None:
        parts = ", ".join(f"{k}: checkpoint has {a!r}, requested {b!r}" for k, (a, b) in mismatches.items())
        super().__init__(f"{path}: checkpoint does not match the requested config ({parts})")
        self.path = path
        self.mismatches = mismatches


class CheckpointFormatError(ValueError):
    """A file that is not a readable PoseNet checkpoint."""


class NoEstimate(Exception):
    """No pose can be estimated: too few valid points (or an empty mask).

    ``num_points`` is the number of valid points found, ``min_points`` the number required.
    """

    def __init__(self, num_points: int, min_points: int, reason: str = "too few valid points") -> None:
        super().__init__(f"no estimate: {reason} ({num_points} < {min_points})")
        self.num_points = num_points
        self.min_points = min_points
        self.reason = reason
