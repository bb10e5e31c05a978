"""Learning curves of RL runs: the periodic evaluation's success rate against env steps and wall
time, read from an RL Zoo run's ``evaluations.npz`` and monitor files (``sms3d train-policy`` on
an RL recipe, ``python -m rl_zoo3.train``), or from the ``progress.csv`` (SB3's CSV logger) of a
run of the package's RL trainer before 0.2.0.

``sms3d learning-curve RUN [RUN ...] --out curve.png`` draws them side by side (one line per run,
e.g. one per training seed) and prints the table. A run of the package's trainer that started
from a checkpoint of another (``init_model: RUN0/checkpoints/ppo_<N>_steps.zip`` in its
``config.json``) is drawn as that run's curve up to ``N`` followed by its own, its steps and wall
time counted on from there: one curve per training.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

from sms3d_env.policies.loader import checkpoint_steps

EVAL_COLUMN, STEPS_COLUMN, WALL_COLUMN = "eval/success_rate", "time/total_timesteps", "time/time_elapsed"
SHARE_COLUMN = "curriculum/pregrasp_start"  # written by the curriculum's annealing
ZOO_EVALUATIONS = "evaluations.npz"  # RL Zoo's EvalCallback's, in the run folder


def _zoo_curve(run: Path) -> list[dict[str, float]]:
    """An RL Zoo run's evaluations (``timesteps`` and per-episode ``successes``), each at the wall
    time when the first training env's monitor file (``0.monitor.csv``; the envs step together)
    had reached its share of those steps, to within one episode; no curriculum share."""
    import numpy as np

    with np.load(run / ZOO_EVALUATIONS, allow_pickle=False) as z:
        if "successes" not in z.files or not len(z["timesteps"]):
            raise ValueError(f"{run / ZOO_EVALUATIONS}: no evaluation with successes")
        steps, success = z["timesteps"], np.asarray(z["successes"], float).mean(axis=1)
    monitors = sorted(run.glob("*.monitor.csv"))
    if not monitors:
        raise FileNotFoundError(f"{run}: no monitor files beside {ZOO_EVALUATIONS}")
    with open(run / "0.monitor.csv", newline="") as f:
        next(f)  # the JSON header line
        episodes = [(float(r["l"]), float(r["t"])) for r in csv.DictReader(f)]
    ends = np.cumsum([length for length, _ in episodes]) * len(monitors)
    walls = [t for _, t in episodes]
    return [{"steps": float(s), "success": float(p), "pregrasp_start": math.nan,
             "wall_s": walls[min(int(np.searchsorted(ends, s)), len(walls) - 1)] if walls else math.nan}
            for s, p in zip(steps, success, strict=True)]


def read_curve(run: str | Path) -> list[dict[str, float]]:
    """``[{"steps", "wall_s", "success", "pregrasp_start"}]`` per periodic evaluation of a run
    folder, in order.

    An RL Zoo run's come from :func:`_zoo_curve`. In a ``progress.csv``, SB3 writes the evaluation
    and the rollout statistics on separate rows; the wall time and the annealed curriculum share
    (NaN for a run without one) of an evaluation row are the latest ones logged before it
    (FileNotFoundError / ValueError name the file when it is missing or has no evaluation)."""
    path = Path(run) / "progress.csv"
    if (Path(run) / ZOO_EVALUATIONS).is_file() and not path.is_file():
        return _zoo_curve(Path(run))
    if not path.is_file():
        raise FileNotFoundError(f"{run}: neither {ZOO_EVALUATIONS} nor progress.csv (an RL run's folder?)")
    points: list[dict[str, float]] = []
    wall = share = math.nan
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row.get(WALL_COLUMN):
                wall = float(row[WALL_COLUMN])
            if row.get(SHARE_COLUMN):
                share = float(row[SHARE_COLUMN])
            if row.get(EVAL_COLUMN):
                points.append({"steps": float(row[STEPS_COLUMN]), "wall_s": wall,
                               "success": float(row[EVAL_COLUMN]), "pregrasp_start": share})
    if not points:
        raise ValueError(f"{path}: no {EVAL_COLUMN} rows (was --eval-freq 0?)")
    start = _started_from(Path(run))
    if start is None:
        return points
    parent, steps = start
    before = [p for p in read_curve(parent) if p["steps"] <= steps]
    wall = _wall_at(parent, steps)
    return before + [{**p, "steps": p["steps"] + steps, "wall_s": p["wall_s"] + wall} for p in points]


def _started_from(run: Path) -> tuple[Path, int] | None:
    """``(run folder, steps)`` of the checkpoint a run was started from (``init_model``), if any."""
    config = run / "config.json"
    init = json.loads(config.read_text()).get("init_model") if config.is_file() else None
    if not init:
        return None
    path = Path(init)
    steps = checkpoint_steps(path)
    if steps is None or path.parent.name != "checkpoints" or not (path.parent.parent / "progress.csv").is_file():
        return None
    if path.parent.parent.resolve() == run.resolve():  # a run cannot continue itself
        return None
    return path.parent.parent, steps


def _wall_at(run: Path, steps: int) -> float:
    """The last wall time a run logged at or before ``steps`` env steps."""
    wall = 0.0
    with open(run / "progress.csv", newline="") as f:
        for row in csv.DictReader(f):
            if row.get(WALL_COLUMN) and float(row[STEPS_COLUMN]) <= steps:
                wall = float(row[WALL_COLUMN])
    return wall


def plot_curves(runs: dict[str, list[dict[str, float]]], path: str | Path) -> None:
    """Two panels: success against env steps and against wall time, one line per run; a run with
    an annealed curriculum also gets its share of curriculum starts, dashed, in the first."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sms3d_env.study.figures import save_figure

    fig, (by_steps, by_wall) = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for label, points in runs.items():
        y = [100 * p["success"] for p in points]
        (line,) = by_steps.plot([p["steps"] / 1e3 for p in points], y, marker=".", label=label)
        if any(math.isfinite(p["pregrasp_start"]) for p in points):
            by_steps.plot([p["steps"] / 1e3 for p in points], [100 * p["pregrasp_start"] for p in points],
                          linestyle="--", color=line.get_color(), label=f"{label}: curriculum starts (%)")
        by_wall.plot([p["wall_s"] / 60 for p in points], y, marker=".", label=label)
    by_steps.set_xlabel("env steps (thousands)")
    by_wall.set_xlabel("wall time (minutes)")
    by_steps.set_ylabel("periodic evaluation success from home (%)")
    for ax in (by_steps, by_wall):
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    by_steps.legend(fontsize=8)
    fig.suptitle("Learning curves")
    fig.tight_layout()
    save_figure(fig, path)


def _cmd(args: Any) -> int:
    import sys

    from sms3d_env.study.figures import check_figure_path, distinct_names

    try:
        check_figure_path(args.out)
        # Runs are labelled by path, so that two runs of one name (seed0 of two sweeps) are two lines.
        runs = {name: read_curve(r) for r, name in zip(args.runs, distinct_names(args.runs), strict=True)}
    except (FileNotFoundError, ValueError) as exc:
        print(f"sms3d learning-curve: error: {exc}", file=sys.stderr)
        return 2
    print("| run | evaluations | last steps | last wall (min) | last success | best success |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, points in runs.items():
        last = points[-1]
        print(f"| {name} | {len(points)} | {last['steps']:.0f} | {last['wall_s'] / 60:.1f} | "
              f"{100 * last['success']:.0f} % | {100 * max(p['success'] for p in points):.0f} % |")
    plot_curves(runs, args.out)
    print(f"wrote {args.out}")
    return 0


def register(subparsers: Any) -> None:
    """Add ``sms3d learning-curve``."""
    p = subparsers.add_parser("learning-curve", help="success of RL runs against env steps and wall time")
    p.add_argument("runs", nargs="+", help="RL run folders (RL Zoo's OUT/ALGO/ENV_N, or one with progress.csv)")
    p.add_argument("--out", required=True, help="PNG to write")
    p.set_defaults(func=_cmd)
