"""What recording demonstrations as a Minari dataset costs per env step: the scripted picker's
episodes on SMS3DPickTrain-v1, the same seeds run three ways: the bare env; inside the
``ExpertLabels`` wrapper alone (the picker called in the wrapper, the labels added to ``info``);
and recorded (``record_datasets``: the wrapper, ``minari.DataCollector``'s per-step buffers and
per-episode HDF5 writes, and ``create_dataset`` at the end). Each way runs ``--repeats`` times,
alternating; the table gives the median.

Usage: python benchmarks/bench_minari.py [--episodes 20] [--mushrooms 25] [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import sms3d_env  # noqa: E402, F401
from sms3d_env.pickers.scripted import ScriptedPicker  # noqa: E402
from sms3d_env.training.demonstrations import ExpertLabels, minari_root, record_datasets  # noqa: E402
from sms3d_env.training.envs import TRAIN_ENV_ID, env_kwargs  # noqa: E402


def _episodes(env: gym.Env, seeds: range, labelled: bool) -> int:
    """Run the scripted picker on ``seeds``; the steps taken. ``labelled``: the picker's action is
    the label ``ExpertLabels`` put in ``info`` (as when recording)."""
    steps = 0
    for seed in seeds:
        picker = None if labelled else ScriptedPicker.for_env(env)
        obs, info = env.reset(seed=seed)
        done = False
        while not done:
            action = info["expert_action"] if labelled else picker(obs)
            obs, _, terminated, truncated, info = env.step(action)
            done, steps = terminated or truncated, steps + 1
    return steps


def bare(seeds: range, mushrooms: int) -> tuple[int, float]:
    env = gym.make(TRAIN_ENV_ID, **env_kwargs(mushrooms))
    t = time.perf_counter()
    steps = _episodes(env, seeds, labelled=False)
    wall = time.perf_counter() - t
    env.close()
    return steps, wall


def labels_only(seeds: range, mushrooms: int) -> tuple[int, float]:
    env = ExpertLabels(gym.make(TRAIN_ENV_ID, **env_kwargs(mushrooms)), ScriptedPicker.for_env)
    t = time.perf_counter()
    steps = _episodes(env, seeds, labelled=True)
    wall = time.perf_counter() - t
    env.close()
    return steps, wall


def recorded(seeds: range, mushrooms: int, root: Path, run: int) -> tuple[int, float]:
    with minari_root(root):
        env = gym.make(TRAIN_ENV_ID, **env_kwargs(mushrooms))
        t = time.perf_counter()
        dataset, = record_datasets([(f"bench/scripted-v{run}", env)], ScriptedPicker.for_env, seeds,
                                   {"picker": "scripted"}, progress=False)
        wall = time.perf_counter() - t
    return dataset.total_steps, wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--mushrooms", type=int, default=25)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    seeds = range(args.seed, args.seed + args.episodes)
    walls: dict[str, list[float]] = {"bare env": [], "ExpertLabels": [], "Minari DataCollector": []}
    steps: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as root:
        for r in range(args.repeats):
            for name, run in (("bare env", lambda: bare(seeds, args.mushrooms)),
                              ("ExpertLabels", lambda: labels_only(seeds, args.mushrooms)),
                              ("Minari DataCollector", lambda r=r: recorded(seeds, args.mushrooms, Path(root), r))):
                steps[name], wall = run()
                walls[name].append(wall)
        size_mb = sum(p.stat().st_size for p in Path(root).rglob("*") if p.is_file()) / args.repeats / 1e6
    assert len(set(steps.values())) == 1, f"the three ways took different steps: {steps}"
    n = steps["bare env"]
    base = statistics.median(walls["bare env"]) / n * 1e3
    print(f"{TRAIN_ENV_ID}, scripted picker, {args.episodes} episodes ({n} steps), {args.mushrooms} mushrooms, "
          f"median of {args.repeats}; dataset {size_mb:.1f} MB")
    print(f"{'way':<22}{'ms/step':>9}{'overhead ms/step':>18}{'overhead':>10}")
    for name, w in walls.items():
        ms = statistics.median(w) / n * 1e3
        print(f"{name:<22}{ms:>9.2f}{ms - base:>18.2f}{100 * (ms - base) / base:>9.1f}%")


if __name__ == "__main__":
    main()
