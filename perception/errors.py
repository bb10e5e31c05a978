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
    """A file that is not a readable checkpoint of the network asked for (the message names it)."""


class PipelineInputError(ValueError):
    """An input the pose pipeline or estimator cannot use (shape, dtype, unit, intrinsics); the
    message says which."""


class NoEstimate(Exception):
    """No pose can be estimated: too few valid points (or an empty mask), or points that fix no
    orientation (:class:`DegenerateCloud`).

    ``num_points`` is the number of valid points found, ``min_points`` the number required.
    """

    def __init__(self, num_points: int, min_points: int, reason: str = "too few valid points") -> None:
        counts = f" ({num_points} < {min_points})" if num_points < min_points else ""
        super().__init__(f"no estimate: {reason}{counts}")
        self.num_points = num_points
        self.min_points = min_points
        self.reason = reason


class DegenerateCloud(NoEstimate):
    """Enough points, but all at one place or on one line: no orientation follows from them (the
    network would still answer, confidently). ``spread_m`` is their standard deviation across
    their main direction, ``min_spread_m`` the least that is accepted."""

    def __init__(self, num_points: int, min_points: int, spread_m: float, min_spread_m: float) -> None:
        super().__init__(num_points, min_points,
                         f"degenerate cloud: {num_points} points spread {1000 * spread_m:.3g} mm across their "
                         f"main direction (need >= {1000 * min_spread_m:g} mm): all at one place or on one line")
        self.spread_m = spread_m
        self.min_spread_m = min_spread_m
