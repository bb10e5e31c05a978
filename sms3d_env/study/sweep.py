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

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_atomic
from generator.run_folder import check_out_path
from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.study.plan import SENSITIVITY_VARIANTS, SweepConfig, Task, plan_tasks
from sms3d_env.study.resume import check_resumable, read_json, settings


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
    recorded = settings(config)
    check_resumable(out / "sweep_config.json", recorded)
    parts.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "sweep_config.json", json.dumps(recorded, sort_keys=True))
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
        rows.extend(read_json(parts / f"{task.name}.json", "delete it and run the sweep again to redo that task"))
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
