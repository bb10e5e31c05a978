"""A descend trigger learned from counterfactual rollouts: one step of policy improvement on the
scripted picker (Tesauro & Galperin 1996, "On-line policy improvement using Monte-Carlo
search"; Bertsekas, Tsitsiklis & Wu 1997, "Rollout algorithms for combinatorial
optimization"), distilled into a stable-baselines3 policy.

Why not PPO: the trigger's decision matters in a few percent of episodes (approach stalls under
20-30 deg of pose error), and PPO's advantage of firing is estimated from returns that differ by
a whole success between unrelated episodes. In eleven PPO runs it learned to fire on every entry
into the trigger's radius or hardly fired at all, and none beat the scripted picker at 30 deg
(docs/results-training.md). Here each label is a
*paired* comparison: a seeded episode replays exactly, so firing at step ``t`` and never firing
differ by that firing alone.

For each training episode (its own seed; a pose error drawn per episode):

1. the scripted picker's episode in the trigger-only residual env, never firing, recording the
   observations at the steps where the trigger can act (approach, within
   :data:`~sms3d_env.training.residual.DESCEND_TRIGGER_RADIUS_M` of the stand-off point);
2. up to ``candidates`` of those steps, evenly spread, each replayed from the same seed with the
   trigger fired there;
3. the label of each: success when fired there minus success never firing (-1, 0 or 1), the gain
   of firing now over leaving the approach to the scripted picker.

A PPO policy's mean (:func:`~sms3d_env.training.imitation.behaviour_clone`) is regressed onto
``0.5 + label - margin``: it estimates ``0.5 + E[gain | observation] - margin`` and so fires
(above :data:`~sms3d_env.training.residual.DESCEND_TRIGGER`) at the first step where the expected
gain of firing exceeds ``margin``. It sees only the trigger-only residual's observation (the
estimated pose, the arm's state, the wrist wrench, the stand-off gap and the tool's motion),
never the true pose.

``train_trigger(TriggerConfig(...))`` writes into ``out``: ``labels/`` (one ``.npz`` per chunk of
episodes, ``episodes_<first>-<last>.npz``, written atomically; a rerun reuses them, so an
interrupted collection resumes and a run grown by more ``episodes`` collects only the missing
ones), ``model.zip``, ``config.json`` (the env and wrapper the policy runs in:
``sms3d sweep --picker residual:OUT/model.zip`` loads it) and ``summary.json``, each atomically.
``out`` is a run folder (:mod:`generator.run_folder`): a rerun with other settings than
``episodes``, ``workers`` and ``torch_threads`` is refused unless ``overwrite``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import read_npz_made_with, write_atomic
from generator.run_folder import open_run_folder
from sms3d_env.training.config import POSTURE_TARGETS, check_bed_size, env_options
from sms3d_env.training.model_files import finished_run, run_settings, save_model

#: Episodes per label file (and per worker task).
CHUNK_EPISODES = 20
#: ``TriggerConfig`` fields a rerun may change: how it is carried out, and more episodes, which
#: extend the run (their labels are collected, the trigger fitted on all; fewer are refused: they
#: would replace the larger run's trigger).
RUN_ONLY_FIELDS = ("workers", "torch_threads")
EXTENSIBLE_FIELDS = ("episodes",)
#: The residual wrapper's scale in the saved configuration: a trigger-only residual does not use
#: it, but ``make_env`` wraps an env only for a positive scale.
TRIGGER_ONLY_SCALE = 1.0


@dataclass(frozen=True)
class TriggerConfig:
    """Settings of :func:`train_trigger`.

    Attributes:
        out: run folder.
        episodes: training episodes, seeds ``seed .. seed + episodes - 1`` (the study's held-out
            episodes start at 1,000,000; keep these apart).
        seed: first episode seed; also seeds the network's initialisation and batches.
        num_mushrooms: mushrooms per bed.
        pose_error_range_deg: (low, high): each episode's orientation error is drawn uniformly
            in it (degrees).
        posture_target: the IK posture option (``sms3d_env.training.config.POSTURE_TARGETS``).
        robot: the robot the trigger acts on (``sms3d_env.robots.ROBOTS``).
        candidates: most replays per episode (steps where the trigger can act, evenly spread).
        margin: the expected gain of firing (success probability, 0-1) the policy needs to fire.
        net_arch, epochs, batch_size, learning_rate: the regression's network and optimiser.
        workers: processes collecting labels (they die with this one).
        torch_threads: torch intra-op threads for the regression.
    """

    out: str = "runs/trigger"
    episodes: int = 1200
    seed: int = 3_000_000
    num_mushrooms: int = 25
    pose_error_range_deg: tuple[float, float] = (15.0, 35.0)
    posture_target: str = "tool"
    robot: str = "gantry"
    candidates: int = 10
    margin: float = 0.15
    net_arch: tuple[int, ...] = (256, 256)
    epochs: int = 30
    batch_size: int = 256
    learning_rate: float = 1e-3
    workers: int = 1
    torch_threads: int = 1

    def __post_init__(self) -> None:
        def bad(name: str, why: str) -> ValueError:
            return ValueError(f"TriggerConfig.{name} {why}, got {getattr(self, name)!r}")

        for name in ("episodes", "num_mushrooms", "candidates", "epochs", "batch_size", "workers", "torch_threads"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise bad(name, "must be an integer >= 1")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise bad("seed", "must be an integer >= 0")
        check_bed_size("TriggerConfig.num_mushrooms", self.num_mushrooms)
        lo_hi = self.pose_error_range_deg
        if (len(lo_hi) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in lo_hi)
                or not 0 <= lo_hi[0] <= lo_hi[1] <= 90):
            raise bad("pose_error_range_deg", "must be (low, high) degrees with 0 <= low <= high <= 90")
        if self.posture_target not in POSTURE_TARGETS:
            raise bad("posture_target", f"must be one of {POSTURE_TARGETS}")
        from sms3d_env.robot_names import ROBOTS

        if self.robot not in ROBOTS:
            raise bad("robot", f"must be one of {ROBOTS}")
        if not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin) and -1 < self.margin < 1):
            raise bad("margin", "must be a number in (-1, 1) (a gain in success probability)")
        if not (isinstance(self.learning_rate, (int, float)) and math.isfinite(self.learning_rate)
                and self.learning_rate > 0):
            raise bad("learning_rate", "must be a number > 0")
        if len(self.net_arch) == 0 or any(int(h) < 1 for h in self.net_arch):
            raise bad("net_arch", "must list at least one layer width >= 1")
        object.__setattr__(self, "pose_error_range_deg", tuple(float(v) for v in lo_hi))
        object.__setattr__(self, "net_arch", tuple(int(h) for h in self.net_arch))

    def label_settings(self, first: int, stop: int) -> dict[str, Any]:
        """What the label file of episodes ``first .. stop - 1`` holds and depends on: a file made
        with other settings, or for other episodes, is not reused for it."""
        return {"num_mushrooms": self.num_mushrooms, "pose_error_range_deg": list(self.pose_error_range_deg),
                "posture_target": self.posture_target, "robot": self.robot, "candidates": self.candidates,
                "episodes": [first, stop]}

    def env_options(self) -> dict[str, Any]:
        """The options beyond the training id's defaults that the trigger acts (and must run) with."""
        return {**env_options(self.posture_target), **({"robot": self.robot} if self.robot != "gantry" else {})}


def trigger_env(cfg: TriggerConfig) -> Any:
    """The env the trigger acts in: ``SMS3DPickTrain-v1`` inside a trigger-only residual (the
    ``ResidualPicker`` is the outermost wrapper)."""
    from sms3d_env.training.envs import make_env
    from sms3d_env.training.imitation import TRAIN_ENV_ID, train_env_kwargs

    return make_env(TRAIN_ENV_ID, TRIGGER_ONLY_SCALE, residual_descend_trigger=True, residual_trigger_only=True,
                    **train_env_kwargs(cfg.num_mushrooms, pose_error_range_deg=cfg.pose_error_range_deg,
                                       posture_target=cfg.posture_target) | cfg.env_options())


def _episode(env: Any, seed: int, fire_at: int | None = None,
             record: bool = False) -> tuple[bool, list[tuple[int, dict[str, np.ndarray]]]]:
    """The seeded episode of the trigger env ``env`` (a ``ResidualPicker``), firing the trigger at
    step ``fire_at`` only (never if None): its success and, with ``record``, the steps where the
    trigger could act and their observations."""
    fire, hold = np.ones(1, np.float32), -np.ones(1, np.float32)
    obs, _ = env.reset(seed=seed)
    reachable, done, step, info = [], False, 0, {}
    while not done:
        if record and env.trigger_can_fire:
            reachable.append((step, {k: np.array(v) for k, v in obs.items()}))  # the env may reuse its arrays
        obs, _, terminated, truncated, info = env.step(fire if step == fire_at else hold)
        done = terminated or truncated
        step += 1
    return bool(info["is_success"]), reachable


def label_episode(env: Any, seed: int, candidates: int) -> tuple[list[dict], list[int], bool]:
    """The labelled observations of one seeded episode of the trigger env ``env`` (see the module
    docstring): their observations, labels (-1, 0, 1) and whether the scripted episode succeeded."""
    base, reachable = _episode(env, seed, record=True)
    if len(reachable) > candidates:
        reachable = [reachable[int(round(i))] for i in np.linspace(0, len(reachable) - 1, candidates)]
    labels = [int(_episode(env, seed, fire_at=t)[0]) - int(base) for t, _ in reachable]
    return [o for _, o in reachable], labels, base


def _label_chunk(cfg: TriggerConfig, first: int, stop: int, path: str) -> str:
    """Label episodes ``first .. stop - 1`` (a chunk) and write them to ``path`` atomically."""
    from generator.files import save_npz_atomic

    env = trigger_env(cfg)
    rows: dict[str, list[np.ndarray]] = {}
    labels, episode, base = [], [], []
    try:
        for seed in range(first, stop):
            observations, ys, success = label_episode(env, seed, cfg.candidates)
            for o in observations:
                for k, v in o.items():
                    rows.setdefault(k, []).append(np.asarray(v, np.float32))
            labels += ys
            episode += [seed] * len(ys)
            base.append(success)
    finally:
        env.close()
    arrays = {k: np.stack(v) for k, v in rows.items()}
    arrays.update(labels=np.asarray(labels, np.int8), episode=np.asarray(episode, np.int64),
                  scripted_success=np.asarray(base, bool))
    save_npz_atomic(Path(path), arrays, cfg.label_settings(first, stop))
    return path


def _label_file(folder: Path, first: int, stop: int) -> Path:
    return folder / f"episodes_{first}-{stop - 1}.npz"


def label_chunks(cfg: TriggerConfig) -> list[tuple[int, int, Path, bool]]:
    """The chunks of ``cfg``'s episodes, in order: ``(first, stop, file, made)``. A file in
    ``out/labels/`` made with these settings covers its episodes where it starts at a chunk's
    first episode and ends within the run (so a run grown by more episodes keeps its last, short
    chunk and adds the missing episodes); the rest is cut into new chunks of ``CHUNK_EPISODES``."""
    folder = Path(cfg.out) / "labels"
    end = cfg.seed + cfg.episodes
    made: dict[int, list[int]] = {}
    for path in folder.glob("episodes_*-*.npz"):
        first, _, last = path.stem.removeprefix("episodes_").partition("-")
        if first.isdigit() and last.isdigit() and int(last) < end:
            made.setdefault(int(first), []).append(int(last) + 1)
    chunks, first = [], cfg.seed
    while first < end:
        stop = next((s for s in sorted(made.get(first, []), reverse=True)
                     if read_npz_made_with(_label_file(folder, first, s), cfg.label_settings(first, s)) is not None),
                    None)
        if stop is not None:
            chunks.append((first, stop, _label_file(folder, first, stop), True))
        else:
            stop = min([first + CHUNK_EPISODES, end, *(f for f in made if f > first)])
            chunks.append((first, stop, _label_file(folder, first, stop), False))
        first = stop
    return chunks


def collect_labels(cfg: TriggerConfig, progress: bool = True) -> dict[str, np.ndarray]:
    """Every chunk's labels (``out/labels/``, :func:`label_chunks`), collecting the chunks not made
    yet; observations per key, ``labels``, ``episode`` and the scripted success of every episode
    (``scripted_success``, per episode, not per label)."""
    from tqdm.auto import tqdm

    from generator.processes import worker_pool

    chunks = label_chunks(cfg)
    chunks[0][2].parent.mkdir(parents=True, exist_ok=True)
    todo = [(first, stop, str(path)) for first, stop, path, made in chunks if not made]
    bar = tqdm(total=len(chunks), initial=len(chunks) - len(todo), desc="trigger labels (chunks)",
               disable=not progress)
    if cfg.workers <= 1:
        for first, stop, path in todo:
            _label_chunk(cfg, first, stop, path)
            bar.update()
    else:
        with worker_pool(cfg.workers) as pool:
            for _ in pool.map(_label_chunk, [cfg] * len(todo), *zip(*todo, strict=True)):
                bar.update()
    bar.close()
    parts = [read_npz_made_with(path, cfg.label_settings(first, stop)) for first, stop, path, _ in chunks]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def fit_trigger(cfg: TriggerConfig, labels: dict[str, np.ndarray], progress: bool = True) -> tuple[Any, list[float]]:
    """A PPO model (``MultiInputPolicy`` on the trigger env's observation) whose mean is
    regressed onto ``0.5 + label - margin``; returns it and the loss per epoch."""
    from sms3d_env.training.imitation import behaviour_clone, build_policy_model

    targets = np.clip(0.5 + labels["labels"].astype(np.float32) - cfg.margin, -1.0, 1.0)[:, None]
    data = {**labels, "actions": targets.astype(np.float32)}
    env = trigger_env(cfg)
    try:
        # The trigger acts deterministically (the mean); the noise matters only to a stochastic
        # rollout, where sigma 0.05 keeps it near the mean.
        model = build_policy_model(env, data, cfg.net_arch, log_std=-3.0, seed=cfg.seed)
    finally:
        env.close()
    losses = behaviour_clone(model, data, cfg.epochs, cfg.batch_size, cfg.learning_rate, cfg.seed, progress)
    return model, losses


def train_trigger(cfg: TriggerConfig, progress: bool = True, overwrite: bool = False) -> dict[str, Any]:
    """Collect (or reuse) the labels, fit the trigger, save ``model.zip``, ``config.json`` and
    ``summary.json`` in ``cfg.out``; returns the summary. ``cfg.out`` is a run folder
    (``RunFolderError`` for one made with other settings or fewer episodes, ``RUN_ONLY_FIELDS``
    aside, unless ``overwrite``); a finished run with these ``episodes`` does nothing."""
    import sms3d_env
    from sms3d_env.training.imitation import TRAIN_ENV_ID
    from sms3d_env.training.threads import torch_threads

    run = open_run_folder(cfg.out, run_settings(asdict(cfg)), overwrite=overwrite, may_change=RUN_ONLY_FIELDS,
                          may_grow=EXTENSIBLE_FIELDS)
    with run:  # holds the folder's lock until the run ends
        out = run.path
        if run.resumed:
            finished = finished_run(out, episodes=cfg.episodes)
            if finished is not None:
                return finished
            run.check_writable()
            # A summary of fewer episodes is not this run's: the run is unfinished until it writes its own.
            (out / "summary.json").unlink(missing_ok=True)
            labelled = sum(stop - first for first, stop, _, made in label_chunks(cfg) if made)
            print(f"resuming {out}: {labelled} of {cfg.episodes} episodes labelled")
        with torch_threads(cfg.torch_threads):
            t0 = time.perf_counter()
            labels = collect_labels(cfg, progress)
            t_labels = time.perf_counter() - t0
            if len(labels["labels"]) == 0:
                raise RuntimeError("no episode reached the trigger's radius: nothing to learn from "
                                   "(check the env options and the pose error range)")
            model, losses = fit_trigger(cfg, labels, progress)
            mean = model.predict({k: labels[k] for k in model.observation_space.spaces}, deterministic=True)[0]
            wall = time.perf_counter() - t0
        from sms3d_env.training.residual import DESCEND_TRIGGER

        config = {"recipe": "trigger-rollouts", "algo": "ppo", "env_id": TRAIN_ENV_ID,
                  "env_options": {**sms3d_env.TRAIN_OPTIONS, **cfg.env_options()},
                  "max_episode_steps": 250, "residual_scale": TRIGGER_ONLY_SCALE,
                  "residual_descend_trigger": True, "residual_trigger_only": True,
                  **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()}}
        write_atomic(out / "config.json", json.dumps(config, indent=2))
        save_model(model, out / "model.zip")
        y = labels["labels"]
        fires = mean[:, 0] > DESCEND_TRIGGER
        summary = {"recipe": "trigger-rollouts", "episodes": cfg.episodes,
                   "scripted_success": float(labels["scripted_success"].mean()),
                   "labelled_states": int(len(y)), "labels": {str(v): int((y == v).sum()) for v in (-1, 0, 1)},
                   "fires_in_labelled_states": int(fires.sum()),
                   "mean_label_where_it_fires": float(y[fires].mean()) if fires.any() else None,
                   "final_loss": losses[-1], "labels_wall_s": round(t_labels, 1), "wall_s": round(wall, 1),
                   "model": str(out / "model.zip")}
        write_atomic(out / "summary.json", json.dumps(summary, indent=2))
        return summary
