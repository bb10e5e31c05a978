"""What a pose-error sweep runs: its settings (``SweepConfig``, checked before anything is
written), the physics variants it may compare, and its tasks (``plan_tasks``): one per chunk of
seeded episodes in each cell of the sweep's axes, each named by its place (its part file's name)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from generator.errors import ConfigError
from sms3d_env.physics_params import PickPhysicsParams

DEFAULT_ERRORS_DEG = (0.0, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0)
# Physics settings with no published source, varied to show how the answer depends on them:
# the lip's compliance S (3 and 7 mm about the default 5 mm), and the root's bending and twisting
# strength halved and doubled (relative to the defaults, so the variants follow any change of
# them). ``benchmarks/bench_tolerance_table.py`` sweeps the cup and the twist-off torque wider.
_DEFAULTS = PickPhysicsParams()
SENSITIVITY_VARIANTS: dict[str, dict[str, float]] = {
    "default": {},
    "tight_seal": {"lip_compliance": _DEFAULTS.lip_compliance * 0.6},
    "loose_seal": {"lip_compliance": _DEFAULTS.lip_compliance * 1.4},
    "strong_root": {"bend_moment": 2 * _DEFAULTS.bend_moment, "twist_torque": 2 * _DEFAULTS.twist_torque},
    "weak_root": {"bend_moment": _DEFAULTS.bend_moment / 2, "twist_torque": _DEFAULTS.twist_torque / 2},
}


@dataclass(frozen=True)
class SweepConfig:
    """What to sweep. ``episodes`` scenes (seeds ``seed .. seed + episodes - 1``) per error."""

    errors_deg: tuple[float, ...] = DEFAULT_ERRORS_DEG
    episodes: int = 40
    seed: int = 0
    num_mushrooms: tuple[int, ...] = (25,)  # bed sizes (an int is one size)
    position_errors_mm: tuple[float, ...] = (0.0,)  # exact cap-top offsets of the noisy source
    position_along_axis: bool = False  # offsets along the estimated axis instead of across it
    tools: tuple[str, ...] = ("suction",)
    robots: tuple[str, ...] = ("gantry",)  # registered robots' names (sms3d_env.robots.registered_robots)
    targets: tuple[str, ...] = ("harvest_ready",)  # target rules (sms3d_env.targets: the study's classes)
    variants: tuple[str, ...] = ("default",)
    perception_episodes: int = 0  # episodes with the perception pose source (default physics)
    perception_detector: str = "shipped"  # stage 1 of the perception episodes: "shipped", "oracle" or a path
    perception_realism: bool = False  # perception episodes see the camera with every realism effect
    chunk: int = 10  # episodes per task (one part file)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    picker: str = "scripted"  # "scripted" or "policy[:PATH]" (sms3d_env.pickers.registry)

    def __post_init__(self) -> None:
        """Raise :class:`~generator.errors.ConfigError` naming the field. Everything is checked
        here, before ``run_sweep`` creates the folder and records the settings in it, so that a
        refused request leaves nothing behind to block the corrected one."""
        from generator.config import SceneConfig

        object.__setattr__(self, "errors_deg", tuple(float(e) for e in self.errors_deg))
        if not self.errors_deg or any(not math.isfinite(e) or not 0 <= e <= 180 for e in self.errors_deg):
            raise ConfigError("errors_deg", f"must be angles in [0, 180] degrees, got {self.errors_deg!r}")
        sizes = (self.num_mushrooms,) if isinstance(self.num_mushrooms, int) else tuple(self.num_mushrooms)
        object.__setattr__(self, "num_mushrooms", sizes)
        object.__setattr__(self, "position_errors_mm", tuple(float(e) for e in self.position_errors_mm))
        object.__setattr__(self, "tools", tuple(self.tools))
        object.__setattr__(self, "robots", tuple(self.robots))
        object.__setattr__(self, "targets", tuple(self.targets))
        if not self.position_errors_mm or any(not math.isfinite(e) or not 0 <= e <= 100
                                              for e in self.position_errors_mm):
            raise ConfigError("position_errors_mm", f"must be distances in [0, 100] mm, got {self.position_errors_mm!r}")
        from sms3d_env.robot import TOOLS

        if not self.tools or any(t not in TOOLS for t in self.tools):
            raise ConfigError("tools", f"must be among {TOOLS}, got {self.tools!r}")
        from sms3d_env.robots import registered_robots

        robots = registered_robots()
        if not self.robots or any(r not in robots for r in self.robots) or len(set(self.robots)) < len(self.robots):
            raise ConfigError("robots", f"must be distinct names among {robots}, got {self.robots!r}")
        from sms3d_env.targets import SWEPT_RULES

        if not self.targets or any(t not in SWEPT_RULES for t in self.targets) or \
                len(set(self.targets)) < len(self.targets):
            raise ConfigError("targets", f"must be distinct target rules among {SWEPT_RULES}, got {self.targets!r}")
        if not sizes or any(isinstance(n, bool) or not isinstance(n, int) for n in sizes):
            raise ConfigError("placement.num_mushrooms", f"must be integers, got {self.num_mushrooms!r}")
        for name, least in (("episodes", 1), ("chunk", 1), ("perception_episodes", 0), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ConfigError(name, f"must be an integer >= {least}, got {value!r}")
        unknown = [v for v in self.variants if v not in SENSITIVITY_VARIANTS]
        if unknown:
            raise ConfigError("variants", f"unknown physics variants {unknown}; choose from {sorted(SENSITIVITY_VARIANTS)}")
        for n in sizes:
            SceneConfig().replace(placement__num_mushrooms=n)  # the generator's own range
        from sms3d_env.pickers.registry import parse_picker

        try:
            parse_picker(self.picker)
        except (ValueError, FileNotFoundError) as exc:
            raise ConfigError("picker", str(exc)) from exc


@dataclass(frozen=True)
class Task:
    variant: str
    error_deg: float  # the noisy source's error; NaN for the perception source (measured instead)
    episode_seeds: tuple[int, ...]
    source: str = "noisy"
    position_error_mm: float = 0.0
    tool: str = "suction"
    num_mushrooms: int = 25
    robot: str = "gantry"
    target: str = "harvest_ready"

    @property
    def name(self) -> str:
        """The part file's name; the axes added later appear only off their historic values, so
        folders of earlier sweeps keep their names."""
        error = "perception" if self.source == "perception" else f"e{self.error_deg:g}"
        extra = (f"_p{self.position_error_mm:g}mm" if self.position_error_mm else "") + \
            (f"_{self.tool}" if self.tool != "suction" else "") + \
            (f"_n{self.num_mushrooms}" if self.num_mushrooms != 25 else "") + \
            (f"_{self.robot}" if self.robot != "gantry" else "") + \
            (f"_t{self.target}" if self.target != "harvest_ready" else "")
        return f"{self.variant}_{error}{extra}_s{self.episode_seeds[0]}-{self.episode_seeds[-1]}"


def _chunks(first: int, count: int, size: int) -> list[tuple[int, ...]]:
    seeds = list(range(first, first + count))
    return [tuple(seeds[i : i + size]) for i in range(0, len(seeds), size)]


def plan_tasks(config: SweepConfig) -> list[Task]:
    chunks = _chunks(config.seed, config.episodes, config.chunk)
    tasks = [Task(v, e, c, "noisy", p, tool, n, robot, target) for robot in config.robots for tool in config.tools
             for n in config.num_mushrooms for target in config.targets for v in config.variants
             for p in config.position_errors_mm for e in config.errors_deg for c in chunks]
    perception = _chunks(config.seed, config.perception_episodes, config.chunk)
    return tasks + [Task("default", math.nan, c, "perception", 0.0, tool, n, robot, target) for robot in config.robots
                    for tool in config.tools for n in config.num_mushrooms for target in config.targets
                    for c in perception]
