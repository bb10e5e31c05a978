"""Demonstration-started pick policies: scripted-picker rollouts, then behaviour cloning of a
stable-baselines3 policy (PPO's ``MultiInputPolicy``, so that ``PPO.load`` and RL fine-tuning
take it as it is).

Demonstrations are collected DART-style (Laskey et al. 2017, "DART: Noise Injection for Robust
Imitation Learning"): the scripted picker acts with Gaussian noise added to its twist command and
every visited state is labelled with the picker's *clean* action, so the clone sees (and learns to
correct) states a little off the picker's own path. Only successful episodes are kept.

The demonstrations and every DAgger round's labelled episodes are Minari datasets
(:mod:`sms3d_env.training.demonstrations`: the executed action in ``actions``, the picker's clean
label in ``infos["expert_action"]``). ``BCConfig.demos`` names datasets to clone (e.g. recorded by
``sms3d record-demos``); without it the recipe records its own.

``train_bc(BCConfig(...))`` writes into ``out``: ``datasets/`` (a Minari datasets folder: its own
demonstrations ``bc/demos-<k>-v0``, one per bed size, and the DAgger rounds
``bc/dagger<round>-<k>-v0``, one per demonstration env; reused by a rerun), ``model.zip``,
``config.json`` (the env id and options the policy needs) and ``summary.json``, each atomically.
``out`` is a run folder (:mod:`generator.run_folder`): a rerun with the same settings resumes (with
the datasets recorded so far) or, finished, does nothing; other settings are refused unless
``overwrite``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_atomic
from generator.run_folder import open_run_folder
from sms3d_env.policies.files import PolicyFileError, parse_json, read_run_text, save_model
from sms3d_env.training.envs import (
    POSTURE_TARGETS,
    TRAIN_ENV_ID,
    check_bed_size,
    env_kwargs,
    env_options,
)


def finished_run(folder: Path) -> dict[str, Any] | None:
    """The summary of the finished run in ``folder``, after saying so: its ``summary.json`` (the
    last file a run writes); None when there is none."""
    path = folder / "summary.json"
    if not path.is_file():
        return None
    try:
        summary = parse_json(read_run_text(path, "run summary"), path, "run summary")
        if not isinstance(summary, dict):
            raise PolicyFileError(path, "not a readable run summary (no JSON object)")
    except PolicyFileError as exc:
        raise PolicyFileError(path, f"{exc.message}; --overwrite to start the run anew") from None
    print(f"{folder} is complete ({path.name}); nothing to do (--overwrite to start it anew)")
    return summary


class NonFiniteLossError(RuntimeError):
    """Behaviour cloning's loss became NaN or infinite: the run stops unfinished."""


@dataclass(frozen=True)
class BCConfig:
    """Demonstration collection and behaviour cloning settings.

    Args:
        demos: Minari dataset ids (under ``MINARI_DATASETS_PATH``) whose labelled episodes to
            clone, recorded on ``SMS3DPickTrain-v2`` with this ``posture_target`` (``sms3d
            record-demos``); their envs also run the DAgger rounds. Empty (default): record the
            demonstrations into ``out/datasets`` as the next five fields say (which are refused
            with ``demos`` given).
        episodes: scripted episodes to run (failures are dropped), split evenly over
            ``num_mushrooms`` bed sizes; episode ``i`` uses ``reset(seed=seed + i)``.
        num_mushrooms: bed sizes the demonstrations cycle through.
        action_noise: standard deviation of the Gaussian noise on the six normalised twist
            commands while collecting (DART); the suction command is left clean.
        pose_error_deg: the noisy pose source's rotation error while collecting (0: oracle).
        pose_error_range_deg: ``(low, high)``: a rotation error drawn per episode in this range
            instead (excludes ``pose_error_deg``).
        posture_target: the env's IK posture option (``SMS3DPickEnv``): ``"tool"`` lets a picker
            that corrects a wrong estimate move away from the estimate's arm configuration;
            recorded in ``config.json`` with the other env options.
        epochs, batch_size, learning_rate, net_arch: the regression of the policy's mean action
            onto the picker's clean actions (mean squared error, Adam).
        log_std: the Gaussian policy's log standard deviation after cloning (exploration of an
            RL fine-tuning; deterministic evaluation uses the mean).
        dagger_rounds, dagger_episodes, dagger_epochs: DAgger (Ross et al. 2011) after the first
            clone: per round, ``dagger_episodes`` episodes in which the clone acts (the picker
            instead with probability 0.5^round) and the picker labels every state, then
            ``dagger_epochs`` more epochs on everything so far. A clone alone stalls at the
            stand-off point: the picker turns suction on there in one step, seen once per
            demonstration; the clone's own hovering states teach it the switch.
    """

    demos: tuple[str, ...] = ()
    episodes: int = 600
    num_mushrooms: tuple[int, ...] = (10, 25)
    action_noise: float = 0.2
    pose_error_deg: float = 0.0
    pose_error_range_deg: tuple[float, float] | None = None
    posture_target: str = "estimate"
    epochs: int = 40
    batch_size: int = 512
    learning_rate: float = 1e-3
    net_arch: tuple[int, ...] = (256, 256)
    log_std: float = -2.0
    dagger_rounds: int = 3
    dagger_episodes: int = 150
    dagger_epochs: int = 15
    seed: int = 0
    out: str = "runs/bc"
    torch_threads: int = 1

    def __post_init__(self) -> None:
        def bad(name: str, why: str) -> ValueError:
            return ValueError(f"BCConfig.{name} {why}, got {getattr(self, name)!r}")

        for name in ("episodes", "epochs", "batch_size", "torch_threads", "dagger_episodes", "dagger_epochs"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "must be an integer >= 1")
        for name in ("seed", "dagger_rounds"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise bad(name, "must be an integer >= 0")
        object.__setattr__(self, "num_mushrooms", tuple(self.num_mushrooms))
        object.__setattr__(self, "net_arch", tuple(self.net_arch))
        object.__setattr__(self, "demos", tuple(self.demos))
        if any(not isinstance(d, str) or not d for d in self.demos):
            raise bad("demos", "must be Minari dataset ids")
        if self.demos:
            defaults = {f.name: f.default for f in fields(self)}
            for name in RECORDING_FIELDS:
                if getattr(self, name) != defaults[name]:
                    raise bad(name, "sets the recording of demonstrations; with demos given they come from "
                                    "those datasets")
        if not self.num_mushrooms:
            raise bad("num_mushrooms", "must be a non-empty sequence of bed sizes")
        for n in self.num_mushrooms:
            check_bed_size("BCConfig.num_mushrooms", n)
        if not self.net_arch or any(isinstance(h, bool) or not isinstance(h, int) or h < 1
                                    for h in self.net_arch):
            raise bad("net_arch", "must be a non-empty sequence of integers >= 1")
        for name in ("action_noise", "pose_error_deg"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise bad(name, "must be a finite number >= 0")
        if self.pose_error_range_deg is not None:
            low_high = tuple(float(v) for v in self.pose_error_range_deg)
            if len(low_high) != 2 or not (0 <= low_high[0] <= low_high[1] <= 180):
                raise bad("pose_error_range_deg", "must be (low, high) with 0 <= low <= high <= 180")
            if self.pose_error_deg > 0:
                raise bad("pose_error_range_deg", "excludes pose_error_deg > 0")
            object.__setattr__(self, "pose_error_range_deg", low_high)
        if self.posture_target not in POSTURE_TARGETS:
            raise bad("posture_target", f"must be one of {POSTURE_TARGETS}")
        if not (isinstance(self.learning_rate, (int, float)) and 0 < self.learning_rate < 1):
            raise bad("learning_rate", "must be in (0, 1)")
        if not (isinstance(self.log_std, (int, float)) and math.isfinite(self.log_std)):
            raise bad("log_std", "must be a finite number")
        if not self.out:
            raise bad("out", "must be a non-empty path")


#: ``BCConfig`` fields that say how the recipe records its own demonstrations.
RECORDING_FIELDS = ("episodes", "num_mushrooms", "action_noise", "pose_error_deg", "pose_error_range_deg")


def _record(cfg: BCConfig, targets: list[tuple[str, Any]], seeds: range, actor: Any = None, beta: float = 1.0,
            desc: str = "demonstrations", progress: bool = True) -> list[Any]:
    """Episodes ``seeds`` labelled by the scripted picker into new datasets ``targets`` (``(id,
    env)`` pairs, episodes cycled over them): the picker acts with DART noise in an episode with
    probability ``beta``, else ``actor`` does while the picker labels its states (DAgger)."""
    from sms3d_env.pickers.scripted import ScriptedPicker
    from sms3d_env.training.demonstrations import record_datasets

    return record_datasets(targets, ScriptedPicker.for_env, seeds,
                           {"picker": "scripted", "made_by": "sms3d train-policy (a bc recipe)"},
                           actor=actor, beta=beta, action_noise=cfg.action_noise,
                           rng=np.random.default_rng([cfg.seed, seeds.start]), desc=desc, progress=progress)


def _reuse_or_record(ids: list[str], record: Any) -> list[Any]:
    """The datasets ``ids`` under Minari's current root if every one is complete (a rerun's),
    else ``record()``'s, after removing what a cut recording left of them."""
    from sms3d_env.training.demonstrations import delete_dataset, open_dataset, recording_of

    if all(recording_of(i) is not None for i in ids):
        return [open_dataset(i) for i in ids]
    for i in ids:
        delete_dataset(i)
    return record()


def given_demos(cfg: BCConfig) -> list[Any]:
    """The datasets ``cfg.demos`` (none: ``[]``), checked to be finite and of the env the clone
    runs in: ``TRAIN_ENV_ID`` with ``cfg.posture_target`` (``DatasetError`` naming the dataset)."""
    from sms3d_env.env_args import translate_legacy_options
    from sms3d_env.training.demonstrations import DatasetError, check_finite, open_dataset

    datasets = [open_dataset(i) for i in cfg.demos]
    for dataset_id, dataset in zip(cfg.demos, datasets, strict=True):
        check_finite(dataset)
        spec = dataset.env_spec
        if spec is None or spec.id != TRAIN_ENV_ID:
            raise DatasetError(f"dataset {dataset_id!r} was recorded on {getattr(spec, 'id', 'an env it cannot rebuild')}; "
                               f"the bc recipe clones on {TRAIN_ENV_ID} (sms3d record-demos --env-id {TRAIN_ENV_ID})")
        controller = translate_legacy_options(spec.kwargs).get("controller") or {}
        posture = controller.get("posture_target", "estimate")
        if posture != cfg.posture_target:
            raise DatasetError(f"dataset {dataset_id!r} was recorded with posture_target={posture!r}; set "
                               f"BCConfig.posture_target (--posture-target) to it")
    return datasets


def own_demos(cfg: BCConfig, root: Path, progress: bool = True) -> list[Any]:
    """The recipe's own demonstrations in the Minari folder ``root``: ``bc/demos-<k>-v0`` for the
    ``k``-th bed size of ``cfg.num_mushrooms``, reused when complete."""
    import gymnasium as gym

    import sms3d_env  # noqa: F401  (registers the env ids)
    from sms3d_env.training.demonstrations import minari_root

    ids = [f"bc/demos-{k}-v0" for k in range(len(cfg.num_mushrooms))]
    with minari_root(root):
        return _reuse_or_record(ids, lambda: _record(
            cfg, [(i, gym.make(TRAIN_ENV_ID, **env_kwargs(n, cfg.pose_error_deg, cfg.pose_error_range_deg,
                                                                cfg.posture_target)))
                  for i, n in zip(ids, cfg.num_mushrooms, strict=True)],
            range(cfg.seed, cfg.seed + cfg.episodes), progress=progress))


def dagger_round(cfg: BCConfig, round_: int, demo_sets: list[Any], actor: Any, root: Path,
                 progress: bool = True) -> list[Any]:
    """DAgger round ``round_``'s labelled episodes in the Minari folder ``root``:
    ``bc/dagger<round_>-<k>-v0`` in the env of the ``k``-th demonstration dataset
    (:func:`~sms3d_env.training.demonstrations.recovered_env`), the clone ``actor`` acting except with probability
    ``0.5**round_``; reused when complete. Seeds from ``cfg.seed + 100000 × round_``, disjoint
    from the demonstrations' and the evaluations'."""
    from sms3d_env.training.demonstrations import minari_root, recovered_env

    first = cfg.seed + 100_000 * round_
    ids = [f"bc/dagger{round_}-{k}-v0" for k in range(len(demo_sets))]
    with minari_root(root):
        return _reuse_or_record(ids, lambda: _record(
            cfg, [(i, recovered_env(d)) for i, d in zip(ids, demo_sets, strict=True)],
            range(first, first + cfg.dagger_episodes), actor, beta=0.5**round_, desc=f"DAgger round {round_}",
            progress=progress))


def flat_observations(demos: dict[str, np.ndarray], keys: list[str]) -> np.ndarray:
    return np.concatenate([demos[k].reshape(len(demos[k]), -1) for k in keys], axis=1)


def build_policy_model(env: Any, demos: dict[str, np.ndarray], net_arch: tuple[int, ...],
                       log_std: float, seed: int) -> Any:
    """A PPO model whose policy standardises observations with the demonstrations' statistics."""
    from stable_baselines3 import PPO

    from sms3d_env.policies.features import NormalizedFlatten

    keys = list(env.observation_space.spaces)
    x = flat_observations(demos, keys)
    # Constant entries (e.g. a zero wrist torque component) keep unit scale.
    std = np.where(x.std(0) > 1e-6, x.std(0), 1.0)
    policy_kwargs = {"net_arch": list(net_arch), "log_std_init": float(log_std),
                     "features_extractor_class": NormalizedFlatten,
                     "features_extractor_kwargs": {"mean": x.mean(0).tolist(), "std": std.tolist()}}
    return PPO("MultiInputPolicy", env, policy_kwargs=policy_kwargs, seed=seed, device="cpu",
               verbose=0)


def behaviour_clone(model: Any, demos: dict[str, np.ndarray], epochs: int, batch_size: int,
                    learning_rate: float, seed: int, progress: bool = True) -> list[float]:
    """Regress the policy's mean action onto the demonstrations' actions; returns the loss per
    epoch. Trains the shared features, the policy network and the action head (not the value).
    ``NonFiniteLossError`` as soon as a batch's loss is NaN or infinite, before it reaches the
    weights."""
    import torch as th
    from tqdm import tqdm

    policy = model.policy
    keys = list(model.observation_space.spaces)
    obs = {k: th.as_tensor(demos[k]) for k in keys}
    target = th.as_tensor(demos["actions"])
    n = len(target)
    params = [p for name, p in policy.named_parameters()
              if not name.startswith(("value_net", "mlp_extractor.value_net", "log_std"))]
    opt = th.optim.Adam(params, lr=learning_rate)
    sched = th.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs)
    gen = th.Generator().manual_seed(seed)
    losses = []
    policy.train()
    for epoch in tqdm(range(epochs), desc="behaviour cloning", disable=not progress, unit="epoch"):
        order = th.randperm(n, generator=gen)
        total = 0.0
        for start in range(0, n, batch_size):
            idx = order[start:start + batch_size]
            features = policy.extract_features({k: v[idx] for k, v in obs.items()})
            latent_pi = policy.mlp_extractor.forward_actor(features)
            mean = policy.action_net(latent_pi)
            loss = th.nn.functional.mse_loss(mean, target[idx])
            if not th.isfinite(loss):
                raise NonFiniteLossError(f"behaviour cloning: the loss became {float(loss.detach())} in epoch {epoch + 1} of "
                                         f"{epochs} (a diverging regression: lower learning_rate, now {learning_rate}); "
                                         "the run stops unfinished, with no model.zip or summary.json")
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        sched.step()
        losses.append(total / n)
    policy.eval()
    return losses


def train_bc(cfg: BCConfig, progress: bool = True, overwrite: bool = False) -> dict[str, Any]:
    """Record (or reuse) demonstrations, clone them, save ``model.zip`` + ``config.json`` +
    ``summary.json`` in ``cfg.out``; returns the summary. ``cfg.out`` is a run folder
    (``RunFolderError`` for one made with other settings, ``torch_threads`` aside, unless
    ``overwrite``); ``cfg.demos`` are checked before it opens (``DatasetError``)."""
    import gymnasium as gym

    import sms3d_env
    from sms3d_env.training.demonstrations import complete_datasets, labelled_steps
    from sms3d_env.training.threads import torch_threads

    demo_sets = given_demos(cfg)
    # The run's settings: its configuration but out, the folder itself (a run moved elsewhere resumes there).
    settings = {k: v for k, v in asdict(cfg).items() if k != "out"}
    run = open_run_folder(cfg.out, settings, overwrite=overwrite, may_change=("torch_threads",))
    with run:  # holds the folder's lock until the run ends
        out = run.path
        root = out / "datasets"
        if run.resumed:
            finished = finished_run(out)
            if finished is not None:
                return finished
            run.check_writable()
            saved = complete_datasets(root)
            print(f"resuming {out}: reusing {', '.join(saved) if saved else 'no recorded dataset yet'}")
        with torch_threads(cfg.torch_threads):
            t0 = time.perf_counter()
            demo_sets = demo_sets or own_demos(cfg, root, progress)
            env = gym.make(TRAIN_ENV_ID, **env_kwargs(cfg.num_mushrooms[0], posture_target=cfg.posture_target))
            keys = list(env.observation_space.spaces)
            demos = labelled_steps(demo_sets, keys)
            t_demo = time.perf_counter() - t0
            try:
                model = build_policy_model(env, demos, cfg.net_arch, cfg.log_std, cfg.seed)
            finally:
                env.close()
            losses = behaviour_clone(model, demos, cfg.epochs, cfg.batch_size, cfg.learning_rate,
                                     cfg.seed, progress)
            data, labelled = demos, list(demo_sets)
            for r in range(1, cfg.dagger_rounds + 1):
                def actor(obs: dict[str, np.ndarray]) -> np.ndarray:
                    return model.predict(obs, deterministic=True)[0]

                labelled += dagger_round(cfg, r, demo_sets, actor, root, progress)
                data = labelled_steps(labelled, keys)
                losses += behaviour_clone(model, data, cfg.dagger_epochs, cfg.batch_size,
                                          cfg.learning_rate, cfg.seed + r, progress)
            wall = time.perf_counter() - t0
        config = {"recipe": "bc", "algo": "ppo", "env_id": TRAIN_ENV_ID,
                  "env_options": {**sms3d_env.TRAIN_OPTIONS, **env_options(cfg.posture_target)},
                  "max_episode_steps": 250,
                  **{k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()}}
        write_atomic(out / "config.json", json.dumps(config, indent=2))
        save_model(model, out / "model.zip")
        summary = {"recipe": "bc", "demos": [d.spec.dataset_id for d in demo_sets],
                   "demo_episodes": int(sum(d.total_episodes for d in demo_sets)),
                   "demo_episodes_kept": int(len(np.unique(demos["episode"]))),
                   "demo_steps": int(len(demos["actions"])), "dagger_rounds": cfg.dagger_rounds,
                   "training_steps": int(len(data["actions"])), "final_loss": losses[-1],
                   "demo_wall_s": round(t_demo, 1), "wall_s": round(wall, 1),
                   "model": str(out / "model.zip")}
        write_atomic(out / "summary.json", json.dumps(summary, indent=2))
        return summary
