"""How accurate must a mushroom's estimated pose be for a pick? The pose-error sweep.

For each orientation error theta (and cap-top position error d, tool and bed size), a picker
(the scripted pose-aware picker by default) runs on the same seeded scenes and targets (a paired
design: only the error differs), with the ``"noisy"`` pose source rotating the oracle pose by
exactly theta about a random axis perpendicular to the stem and moving its cap top by exactly d
perpendicular to the estimated axis (or along it). Results are written one part file per task
(atomic rename), so a killed sweep resumes where it stopped, and the same seed gives the same
numbers whatever the number of workers or the backend (processes or Ray).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from generator.dataset.errors import CorruptFileError
from generator.errors import ConfigError
from generator.files import write_atomic
from generator.run_folder import check_out_path
from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.pickers.registry import SCRIPTED_ENV_ID, picker_name
from sms3d_env.study.report import write_report

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


def target_features(scene: Any, target: int) -> dict[str, float]:
    """Tilt (deg), cap diameter (m) and distance to the nearest neighbour's stem base (m)."""
    inst = scene.instances[target]
    tilt = math.degrees(math.acos(float(np.clip(inst.stem_axis[2], -1.0, 1.0))))
    others = [m.stem_base for m in scene.instances if m.id != inst.id]
    nearest = min((float(np.linalg.norm((o - inst.stem_base)[:2])) for o in others), default=math.inf)
    return {"tilt_deg": tilt, "cap_diameter": inst.cap_diameter, "nn_distance": nearest}


def run_task(task: Task, config: SweepConfig) -> list[dict[str, Any]]:
    """Run one task's episodes in this process and return one row per episode."""
    from sms3d_env.pickers.episode import run_episode
    from sms3d_env.pickers.registry import make_picker_env, parse_picker
    from sms3d_env.pose_sources.noisy import NoisyPose

    physics = PickPhysicsParams(**SENSITIVITY_VARIANTS[task.variant])
    if task.source == "perception":
        from sms3d_env.pose_sources.perception import PerceptionPose

        source: Any = PerceptionPose(detector=config.perception_detector, realism=config.perception_realism)
    else:
        source = NoisyPose(task.error_deg, position_error=task.position_error_mm / 1000,
                           along_axis=config.position_along_axis)
    spec = parse_picker(config.picker)
    tool = {} if task.tool == "suction" else {"tool": task.tool}  # the picker's env may fix it
    env, picker = make_picker_env(
        spec, scene={"placement": {"num_mushrooms": task.num_mushrooms}},  # the env's own placement
        pose_source=source, physics=physics, robot=task.robot, target=task.target, **tool, **config.env_kwargs,
    )
    rows = []
    try:
        for seed in task.episode_seeds:
            result = run_episode(env, picker, seed)
            perceived = task.source == "perception"
            axis_error = source.last_axis_error_deg if perceived else task.error_deg
            cap_top_error = source.last_cap_top_error_mm if perceived else task.position_error_mm
            rows.append({
                "variant": task.variant, "picker": spec.label, "source": task.source,
                "error_deg": task.error_deg, "position_error_mm": task.position_error_mm,
                "robot": task.robot, "tool": task.tool, "num_mushrooms": task.num_mushrooms,
                "target_rule": task.target,
                "axis_error_deg": axis_error, "cap_top_error_mm": cap_top_error, **result,
                **target_features(env.unwrapped.scene, result["target"]),
            })
    finally:
        env.close()
    return rows


def _run_and_save(task: Task, config: SweepConfig, parts: Path) -> str:
    rows = run_task(task, config)
    write_atomic(parts / f"{task.name}.json", json.dumps(rows, sort_keys=True))
    return task.name


# Settings that change what a part file holds without changing its name: a folder's parts can
# only be reused by a sweep that agrees on them (errors, episodes and variants may grow).
RESUME_KEYS = ("env_id", "seed", "chunk", "env_kwargs", "picker", "picker_sha256", "position_along_axis")
# The same for the perception parts alone (the pose-error parts never see a camera), plus the
# digest of the pose weights when the sweep asks for perception episodes.
PERCEPTION_RESUME_KEYS = ("perception_detector", "perception_realism")
# The env generation a sweep's rows come from: parts made on another (v0's ghost Jaco) are not reused.
SWEEP_ENV_ID = SCRIPTED_ENV_ID
# What a folder recorded before a key existed (its parts were made with this value).
_RESUME_DEFAULTS = {"env_id": "SMS3DPick-v0", "picker": "scripted", "picker_sha256": None, "position_along_axis": False,
                    "perception_realism": False}


def _pose_weights_digest(config: SweepConfig) -> str:
    """SHA-256 (16 hex digits) of the weights the perception episodes use: the shipped axis
    CNN, and the stage-1 detector's file unless it is the oracle."""
    import hashlib

    from perception.detection.load import SHIPPED_SEGMENTER
    from perception.pose.axis_cnn import SHIPPED_AXIS_CNN

    digest = hashlib.sha256(SHIPPED_AXIS_CNN.read_bytes())
    if config.perception_detector != "oracle":
        detector = SHIPPED_SEGMENTER if config.perception_detector == "shipped" else Path(config.perception_detector)
        if detector.is_file():  # a missing file is named when the episodes load it
            digest.update(detector.read_bytes())
    return digest.hexdigest()[:16]


def _picker_digests(config: SweepConfig) -> dict[str, str] | None:
    """SHA-256 (16 hex digits) of each file a learned picker loads, by path: its model, and its
    run's ``config.json`` (the env options it acts in) and observation statistics where it has
    them; None for the scripted picker."""
    import hashlib

    from sms3d_env.pickers.registry import parse_picker
    from sms3d_env.policies.loader import observation_stats_path, saved_config_path

    model = parse_picker(config.picker).model_path
    if model is None:
        return None
    files = [f for f in (model, saved_config_path(model), observation_stats_path(model)) if f is not None]
    return {str(f): hashlib.sha256(f.read_bytes()).hexdigest()[:16] for f in files}


def _settings(config: SweepConfig) -> dict[str, Any]:
    """What ``sweep_config.json`` records: the config, the pose weights behind perception parts
    and the learned picker's files."""
    digest = _pose_weights_digest(config) if config.perception_episodes else None
    return json.loads(json.dumps({**dataclasses.asdict(config), "env_id": SWEEP_ENV_ID, "pose_weights_sha256": digest,
                                  "picker_sha256": _picker_digests(config)}, default=str))


def _read_json(path: Path, remedy: str) -> Any:
    """``path``'s JSON, or :class:`CorruptFileError` naming the file (truncated, not text)."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError
        raise CorruptFileError(path, f"not readable JSON ({exc}); {remedy}") from exc


def _difference(key: str, recorded: Any, requested: Any) -> str:
    """A resume setting that differs, as the refusal names it: the learned picker's files by path."""
    if key != "picker_sha256":
        return f"{key}: folder has {recorded!r}, requested {requested!r}"
    # Records from before the config.json was hashed hold the model's digest alone (a string).
    old, new = (d if isinstance(d, dict) else {} for d in (recorded, requested))
    changed = sorted(f for f in old.keys() | new.keys() if old.get(f) != new.get(f))
    return f"picker files changed since the parts were made: {', '.join(changed)}"


def _check_resumable(path: Path, requested: dict[str, Any]) -> None:
    # Only parts could be reused with the wrong settings: a folder without any (its sweep
    # stopped before a task finished) takes the new settings.
    if not any(path.parent.glob("parts/*.json")):
        return
    if not path.is_file():
        # Parts arrive without their settings when copied from another sweep; reusing them
        # unchecked could mix episodes of other physics, pickers or pose weights.
        raise ValueError(f"{path.parent} holds parts but no {path.name}, so their settings are unknown; copy the "
                         f"{path.name} of the sweep that made them beside them, or use another --out")
    stored = _read_json(path, "remove the folder or use another --out")
    if "env_kwargs" in stored:  # a folder of an earlier version names the env options as that version did
        from sms3d_env.env_args import translate_legacy_options

        stored["env_kwargs"] = translate_legacy_options(stored["env_kwargs"])
    old_size = stored.get("num_mushrooms")
    if isinstance(old_size, int) and old_size != 25:
        # Before bed sizes were axes, a part's name did not say its size (25 is named by none).
        raise ValueError(f"{path.parent} holds a sweep of {old_size}-mushroom beds made before bed "
                         f"sizes were named in part files; use another --out")
    keys = list(RESUME_KEYS)
    if any(path.parent.glob("parts/*_perception_*.json")):
        keys += PERCEPTION_RESUME_KEYS
        if requested["pose_weights_sha256"] is not None:
            keys.append("pose_weights_sha256")  # perception parts made with other weights are stale
    differ = {k: (stored.get(k, _RESUME_DEFAULTS.get(k)), requested[k]) for k in keys
              if stored.get(k, _RESUME_DEFAULTS.get(k)) != requested[k]}
    if differ:
        details = ", ".join(_difference(k, a, b) for k, (a, b) in differ.items())
        raise ValueError(f"{path.parent} holds a sweep with other settings ({details}); use another --out")


BACKENDS = ("process", "ray")


def run_sweep(config: SweepConfig, out: str | Path, workers: int = 1, progress: bool = True,
              backend: str = "process") -> list[dict[str, Any]]:
    """Run every task not already in ``out/parts`` and return all rows (ordered, deterministic:
    the same rows whatever ``workers`` and ``backend``, ``"process"`` or ``"ray"``)."""
    from tqdm.auto import tqdm

    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    out = check_out_path(out)
    parts = out / "parts"
    settings = _settings(config)
    _check_resumable(out / "sweep_config.json", settings)
    parts.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "sweep_config.json", json.dumps(settings, sort_keys=True))
    tasks = plan_tasks(config)
    todo = [t for t in tasks if not (parts / f"{t.name}.json").exists()]
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="sweep tasks", disable=not progress)
    if backend == "ray":
        _run_ray(todo, config, parts, workers, bar.update)
    elif workers <= 1:
        for task in todo:
            _run_and_save(task, config, parts)
            bar.update()
    else:
        from generator.processes import worker_pool

        # Workers die with this process: an orphan would keep writing parts beside a resumed sweep.
        with worker_pool(workers) as pool:
            for _ in pool.map(_run_and_save, todo, [config] * len(todo), [parts] * len(todo)):
                bar.update()
    bar.close()
    rows = []
    for task in tasks:
        rows.extend(_read_json(parts / f"{task.name}.json", "delete it and run the sweep again to redo that task"))
    return rows


def _run_ray(todo: list[Task], config: SweepConfig, parts: Path, workers: int, update: Any) -> None:
    """The tasks as Ray tasks (a local cluster of ``workers`` CPUs that ends with this process,
    unless one is running), each writing its part file as in the process pool."""
    try:
        import ray
    except ImportError as exc:
        raise RuntimeError("backend 'ray' needs Ray: pip install 'sms3d-pick[ray]'") from exc
    if not ray.is_initialized():
        from generator.processes import init_ray

        # Its processes end with this one: an orphan would keep writing parts beside a resumed sweep.
        init_ray(max(workers, 1))
    remote = ray.remote(_run_and_save)
    pending = [remote.remote(task, config, parts) for task in todo]
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        ray.get(ready)
        update()


def _cmd_sweep(args: Any) -> int:
    import shlex
    import sys

    try:
        config = SweepConfig(
            errors_deg=tuple(args.errors), episodes=args.episodes, seed=args.seed,
            num_mushrooms=args.num_mushrooms, variants=tuple(args.variants), chunk=args.chunk,
            perception_episodes=args.perception_episodes, perception_detector=args.perception_detector,
            perception_realism=args.perception_realism, picker=args.picker, position_errors_mm=tuple(args.position_errors_mm),
            position_along_axis=args.position_along_axis, tools=tuple(args.tool), robots=tuple(args.robot),
            targets=tuple(args.target),
            env_kwargs={} if args.posture_target == "estimate" else {"controller": {"posture_target": args.posture_target}},
        )
    except ConfigError as exc:
        print(f"sms3d sweep: error: argument {SWEEP_FLAGS.get(exc.field, exc.field)}: {exc.message}", file=sys.stderr)
        return 2
    try:
        rows = run_sweep(config, args.out, workers=args.workers, backend=args.backend)
    except (ValueError, CorruptFileError, RuntimeError) as exc:
        print(f"sms3d sweep: error: {exc}", file=sys.stderr)
        return 2
    command = "sms3d " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["sweep"] else ""
    paths = write_report(rows, args.out, command)
    print(Path(paths["md"]).read_text(encoding="utf-8"))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def load_rows(folder: str | Path) -> list[dict[str, Any]]:
    """Every row of a sweep folder's part files (any order of tasks; sorted by name)."""
    parts = sorted(Path(folder, "parts").glob("*.json"))
    if not parts:
        raise FileNotFoundError(f"{folder} holds no sweep parts (run sms3d sweep --out {folder} first)")
    rows: list[dict[str, Any]] = []
    for path in parts:
        rows.extend(_read_json(path, "delete it and run the sweep again to redo that task"))
    return rows


def _cmd_compare(args: Any) -> int:
    import sys

    from sms3d_env.study.figures import check_figure_path, distinct_names
    from sms3d_env.study.report import plot_pickers

    try:
        check_figure_path(args.out)
        curves: dict[str, list[dict[str, Any]]] = {}
        sweeps = {}
        for folder, name in zip(args.sweeps, distinct_names(args.sweeps), strict=True):
            rows = compared_rows(load_rows(folder))
            if not rows:
                raise ValueError(f"{folder} holds no episodes of the noisy pose source with the default "
                                 "physics, the ones compared; rerun it with --variants default")
            label = picker_name(rows[0].get("picker", "scripted"))
            # Two sweeps of one picker (e.g. with other env options) keep both curves.
            label = label if label not in curves else f"{label} ({name})"
            curves[label], sweeps[folder] = rows, rows
        check_paired(sweeps)
    except (FileNotFoundError, CorruptFileError, ValueError) as exc:
        print(f"sms3d sweep-compare: error: {exc}", file=sys.stderr)
        return 2
    print(picker_comparison(curves))
    plot_pickers(curves, args.out)
    print(f"wrote {args.out}")
    return 0


def compared_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The episodes ``sweep-compare`` sets side by side: the noisy pose source with the default
    physics, in the sweep's base slice (its first tool and bed size, smallest position error)."""
    from sms3d_env.study.report import base_slice
    from sms3d_env.study.statistics import axes

    default = [r for r in rows if r.get("source", "noisy") == "noisy" and r["variant"] == "default"]
    if not default:
        return []
    base = base_slice(default)
    return [r for r in default if axes(r) == base]


def _spans(values: list[int]) -> str:
    """Sorted integers as runs: ``0–39`` or ``0, 2, 5–9``."""
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    return ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in runs)


def _design(rows: list[dict[str, Any]]) -> dict[str, str]:
    """What must be the same in two sweeps' ``compared_rows`` for their episodes to pair."""
    from sms3d_env.study.statistics import axes

    robot, tool, size, target, position = axes(rows[0])
    return {"robot": robot, "tool": tool, "bed size": f"{size} mushrooms", "target": target,
            "position error": f"{position:g} mm",
            "errors": ", ".join(f"{e:g}°" for e in sorted({r["error_deg"] for r in rows})),
            "seeds": _spans(sorted({int(r["seed"]) for r in rows})),
            "episodes": f"{len(rows)} (error, seed) pairs"}


def check_paired(sweeps: dict[str, list[dict[str, Any]]]) -> None:
    """ValueError naming the sweeps and the settings they differ in, unless every sweep's
    ``compared_rows`` ran the same seeded episodes as the first's: a comparison of other beds or
    seeds would pair nothing (McNemar p = nan) or unlike episodes."""
    (first, first_rows), *others = sweeps.items()
    episodes = {(r["error_deg"], r["seed"]) for r in first_rows}
    design = _design(first_rows)
    problems = []
    for folder, rows in others:
        theirs = _design(rows)
        differ = [k for k in design if design[k] != theirs[k]]
        if not differ and {(r["error_deg"], r["seed"]) for r in rows} != episodes:
            differ = ["episodes"]  # as many, but others (an unfinished sweep's)
        if not differ:
            continue
        problems.append(f"{folder}: " + ", ".join(f"{k} {theirs[k]} ({first}: {design[k]})" for k in differ))
    if problems:
        raise ValueError("the sweeps did not run the same seeded episodes, so they cannot be paired: "
                         + "; ".join(problems) + " (compare sweeps run with the same --num-mushrooms, --seed, "
                         "--episodes, --errors and --position-errors-mm)")


def picker_comparison(curves: dict[str, list[dict[str, Any]]]) -> str:
    """Markdown: each picker's success per orientation error on its ``compared_rows`` (reachable
    targets) and the exact McNemar p against the first picker on the episodes both ran (paired
    by seed)."""
    from sms3d_env.study.statistics import mcnemar_p, wilson_interval

    def outcomes(rows: list[dict[str, Any]]) -> dict[float, dict[int, bool]]:
        """Per error, seed -> success of the reachable targets."""
        by_error: dict[float, dict[int, bool]] = {}
        for r in rows:
            if r["reachable"]:
                by_error.setdefault(r["error_deg"], {})[r["seed"]] = bool(r["success"])
        return by_error

    first_label, *_ = curves
    first = outcomes(curves[first_label])
    lines = [f"| picker | error | success | 95 % CI | McNemar p vs {first_label} |", "| --- | --- | --- | --- | --- |"]
    for label, rows in curves.items():
        for error, wins in sorted(outcomes(rows).items()):
            k, n = sum(wins.values()), len(wins)
            lo, hi = wilson_interval(k, n)
            shared = sorted(set(wins) & set(first.get(error, {})))
            p = mcnemar_p([wins[s] for s in shared], [first[error][s] for s in shared]) if shared else float("nan")
            lines.append(f"| {label} | {error:g}° | {k}/{n} = {100 * k / n:.1f} % | {100 * lo:.1f}–{100 * hi:.1f} % | {p:.3g} |")
    return "\n".join(lines)


# The flag that sets each field SweepConfig checks, to report a refused value by what was typed.
SWEEP_FLAGS = {"errors_deg": "--errors", "episodes": "--episodes", "chunk": "--chunk", "seed": "--seed",
               "position_errors_mm": "--position-errors-mm", "tools": "--tool", "robots": "--robot", "targets": "--target",
               "perception_episodes": "--perception-episodes", "variants": "--variants",
               "placement.num_mushrooms": "--num-mushrooms", "picker": "--picker"}


def register(subparsers: Any) -> None:
    """Add ``sms3d sweep``."""
    from sms3d_env.robots import registered_robots

    p = subparsers.add_parser("sweep", help="pick success of a picker against orientation and position error")
    p.add_argument("--out", required=True, help="output folder (resumes if it holds earlier parts)")
    p.add_argument("--errors", type=float, nargs="+", default=list(DEFAULT_ERRORS_DEG),
                   help="errors in degrees, each in [0, 180]")
    p.add_argument("--episodes", type=int, default=40, help="seeded episodes per error (>= 1, default 40)")
    p.add_argument("--seed", type=int, default=0, help="first episode seed (>= 0)")
    p.add_argument("--num-mushrooms", type=int, nargs="+", default=[25],
                   help="mushrooms per bed; several values make bed size an axis of the sweep")
    p.add_argument("--position-errors-mm", type=float, nargs="+", default=[0.0],
                   help="cap-top position errors (mm, exact, perpendicular to the estimated stem "
                        "axis) crossed with --errors: the 2-D map")
    p.add_argument("--position-along-axis", action="store_true",
                   help="offset the cap top along the estimated axis instead of across it")
    p.add_argument("--tool", nargs="+", default=["suction"], choices=["suction", "hand"],
                   help="tools to sweep (the scripted picker for each)")
    p.add_argument("--robot", nargs="+", default=list(SweepConfig.robots), choices=registered_robots(),
                   help="robots to sweep (registered names; several make the robot an axis: a robot column in "
                        "sweep.csv, a curve and a map per robot)")
    from sms3d_env.targets import SWEPT_RULES

    p.add_argument("--target", nargs="+", default=list(SweepConfig.targets), choices=SWEPT_RULES,
                   help="target rules (which mushroom each episode picks: harvest_ready, the env's default, or "
                        "a class of the study); several make the target an axis, a curve and a map per rule")
    p.add_argument("--backend", choices=BACKENDS, default="process",
                   help="process pool (default) or Ray (same rows)")
    p.add_argument("--variants", nargs="+", default=["default"], choices=sorted(SENSITIVITY_VARIANTS),
                   help="physics settings to compare (sensitivity to unsourced assumptions)")
    p.add_argument("--perception-episodes", type=int, default=SweepConfig.perception_episodes,
                   help="also run this many episodes with the perception pose source (shipped segmenter and axis CNN)")
    p.add_argument("--perception-detector", default=SweepConfig.perception_detector,
                   help="stage 1 of the perception episodes: 'shipped' (the shipped RGB-D segmenter, default), "
                        "'oracle' (MuJoCo's segmentation masks) or a train-segmenter/train-detector checkpoint")
    p.add_argument("--perception-realism", action="store_true",
                   help="the perception episodes' overhead camera has every realism effect (stereo noise and "
                        "shadows, flying pixels, RGB noise, lighting, camera jitter; as `sms3d generate --realism`)")
    p.add_argument("--picker", default=SweepConfig.picker,
                   help="scripted (default), policy (the shipped policy) or policy:PATH/model.zip; every "
                        "picker sees the same seeded episodes")
    p.add_argument("--posture-target", choices=("estimate", "tool"), default="estimate",
                   help="the env's IK posture (ControllerConfig.posture_target): estimate (default) or tool; "
                        "a learned picker's own recorded option wins")
    p.add_argument("--chunk", type=int, default=SweepConfig.chunk, help="episodes per resumable task (>= 1)")
    p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 1)), help="processes")
    p.set_defaults(func=_cmd_sweep)

    c = subparsers.add_parser("sweep-compare", help="one figure of several sweeps' pickers (success vs error)")
    c.add_argument("sweeps", nargs="+", help="sweep folders (each run with its own --picker, on the same "
                                             "--num-mushrooms, --seed, --episodes and --errors)")
    c.add_argument("--out", required=True, help="PNG to write")
    c.set_defaults(func=_cmd_compare)
