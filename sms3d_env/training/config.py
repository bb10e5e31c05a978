"""What a reinforcement-learning run depends on: ``TrainConfig`` (saved as ``config.json`` beside
the model) and the env arguments it makes (``env_kwargs``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from sms3d_env.policies.spec import ALGOS

POSE_SOURCES = ("oracle", "noisy")
REWARD_TYPES = ("dense", "sparse", "staged")
#: The ids a policy can be trained on: the base ids (whose ``reward_type`` is an option) and the
#: training ids (the learnable options, the staged reward among them); v1 ids are superseded.
BASE_ENV_IDS = ("SMS3DPick-v2", "SMS3DPick-v1")
TRAIN_ENV_IDS = ("SMS3DPickTrain-v2", "SMS3DPickTrain-v1")
ENV_IDS = BASE_ENV_IDS + TRAIN_ENV_IDS
VEC_ENVS = ("subproc", "dummy")
POSTURE_TARGETS = ("estimate", "tool")  # = sms3d_env.controller.POSTURE_TARGETS (kept free of mink here)


def check_bed_size(field: str, value: Any) -> None:
    """``generator.errors.ConfigError`` (a ``ValueError``) naming ``field`` unless ``value`` is a
    bed size the generator makes (its own range), so that a command refuses it before it writes
    anything, not when it builds its envs."""
    import generator
    from generator.errors import ConfigError

    try:
        generator.SceneConfig().replace(placement__num_mushrooms=value)
    except ConfigError as exc:
        raise ConfigError(field, exc.message) from None


def env_options(posture_target: str = "estimate") -> dict[str, Any]:
    """The env options beyond the env id's defaults that a policy is trained (and must be run)
    with, as JSON (a run's ``config.json`` keeps them): the controller's posture target."""
    return {} if posture_target == "estimate" else {"controller": {"posture_target": posture_target}}


#: Experiments removed from the package on 2026-12-07 because they measured no gain (CHANGELOG.md,
#: Unreleased, "Removed"; docs/results-training.md; git history keeps their code): what the
#: refusal of a recipe, a run, a picker name or a field that asks for one says.
REMOVED_EXPERIMENTS = {
    "residual": "residual PPO on top of the scripted picker was removed on 2026-12-07: it never beat the "
                "scripted picker (at best 88 / 85 % against 83 / 85 % at 20 / 30 deg, p 0.06 / 1.0; "
                "docs/results-training.md; git history keeps it)",
    "trigger": "the learned descend trigger (sms3d train-trigger, --picker residual) was removed on 2026-12-07: "
               "on v1 it picked no more than the scripted picker (McNemar p >= 0.25; docs/results-training.md; "
               "git history keeps it)",
    "teacher": "the privileged teacher (teacher: truth) was removed on 2026-12-07: its clone picked 24 % at 30 deg "
               "against the scripted picker's 78 % (docs/results-training.md; git history keeps it)",
}


def removed_experiment_of(saved: dict[str, Any]) -> str | None:
    """Why a run's ``config.json`` cannot be used when its run was a removed experiment (a residual
    or the descend trigger, whose actions corrected the scripted picker's in a removed wrapper);
    None for any other run."""
    if not saved.get("residual_scale"):
        return None
    return REMOVED_EXPERIMENTS["trigger" if saved.get("residual_descend_trigger") else "residual"]


#: Fields of earlier versions, removed because the runs that used them measured worse or served a
#: removed experiment (what replaced them and the measurement: CHANGELOG.md, "Removed").
REMOVED_FIELDS = {
    **{name: "removed on 2026-12-06 (measured worse; sms3d-pick 0.1.0 still has it)"
       for name in ("residual_until_held", "residual_approach_only", "residual_descend_trigger",
                    "residual_trigger_only", "trigger_log_std", "trigger_log_std_final", "time_limit_terminal",
                    "critic_warmup_steps", "use_sde", "sde_sample_freq")},
    "residual_scale": REMOVED_EXPERIMENTS["residual"],
    "teacher": REMOVED_EXPERIMENTS["teacher"],
}
#: What older runs record for a removed field left at its default, besides None, False, 0 and -1.
REMOVED_FIELD_DEFAULTS = {"teacher": "estimate"}


def removed_fields_set(values: dict[str, Any]) -> list[str]:
    """The :data:`REMOVED_FIELDS` that ``values`` (a run's config.json, a recipe) sets to anything
    but their old defaults (None, False, 0, -1 or :data:`REMOVED_FIELD_DEFAULTS`: what older runs
    record for an option left off)."""
    return sorted(name for name, value in values.items() if name in REMOVED_FIELDS
                  and value not in (None, False, 0, -1, REMOVED_FIELD_DEFAULTS.get(name)))


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on (saved as ``config.json`` next to the model).

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        total_steps: environment steps over all envs.
        max_wall_s: stop early (after the current step) once this many seconds have passed.
        n_envs: parallel envs, stepped as ``vec_env`` says.
        vec_env: ``"subproc"`` (default): one worker process per env when ``n_envs`` > 1
            (SB3's ``SubprocVecEnv``); ``"dummy"``: every env in the training process, one after
            another (``DummyVecEnv``). On 2 cores ``"dummy"`` ran ≈ 6 % faster and leaves the
            second core free (docs/results-training.md).
        flat_observation: the dict observation flattened into one vector (gymnasium's
            ``FlattenObservation``, outermost) and SB3's ``MlpPolicy`` on it instead of
            ``MultiInputPolicy``: the same inputs and network, one normalisation and one tensor
            per step instead of one per observation key (×1.4 steps/s here). Saved in
            ``config.json`` with the flattening order (``observation_keys``); ``PolicyActor``
            flattens dict observations so.
        pose_source, pose_error_deg, position_noise: the target pose estimate used in training
            (``position_noise`` > 0, m: the env's ``pose_source`` is ``NoisyPose(pose_error_deg,
            position_std=position_noise)``).
        env_id: ``"SMS3DPick-v1"`` (default; its options as given here) or ``"SMS3DPickTrain-v1"``
            (the learnable options: latched suction, staged reward, dead-end episode end, task
            observations; ``reward_type`` is then ignored and must stay at its default), or
            their v2 ids (``ENV_IDS``).
        normalize: standardise observations with running statistics (``VecNormalize``).
        normalize_reward: also scale training rewards by the running standard deviation of the
            discounted return (``VecNormalize(norm_reward=True)``; needs ``normalize``; logs,
            evaluations and ``is_success`` keep the true rewards). Why: SB3's PPO clips the norm
            of the policy's and the value function's gradients *together* (``max_grad_norm``
            0.5), and the staged reward's success step pays up to 249 at once, so a rollout with
            successes has value gradients that shrink its own policy step. Measured on the
            checkpoints of a seed-0 run with raw rewards: the policy step of a minibatch was scaled by
            0.007 on a rollout with successes (returns up to 141) against 0.04 on one without
            (docs/results-training.md).
        scene_pool: > 0: each env draws its beds from a pool of this many
            (``SceneSourceConfig.pool``; resets then cost physics, not placement and compilation).
        pose_error_range_deg: ``(low, high)``: train under a pose error drawn per episode
            uniformly in that range (the env's ``pose_error_deg=(low, high)``; ``pose_source``
            must then be ``"noisy"``, ``pose_error_deg`` and ``position_noise`` 0).
        reward_type: ``"dense"``, ``"sparse"`` or ``"staged"``.
        num_mushrooms: mushrooms per generated scene.
        max_episode_steps: episode limit (the registered env uses 250).
        eval_freq, checkpoint_freq: in total env steps; 0 disables.
        eval_episodes: episodes per periodic evaluation (oracle poses, same scenes per eval).
        learning_rate, batch_size, n_steps (PPO, per env), buffer_size and learning_starts (SAC),
        gamma, net_arch: algorithm hyper-parameters.
        learning_rate_final: ``None``: a constant ``learning_rate``; else the rate falls linearly
            from ``learning_rate`` at the first step to this at ``total_steps`` (SB3's
            ``LinearSchedule``; the PPO paper anneals its rate so), so that one run lowers the rate
            that a second phase, started from the first's checkpoint, lowered by hand. The schedule runs over
            ``total_steps``: with ``max_wall_s``, set ``total_steps`` to what fits in it (PPO on 2
            envs here: 280–420 steps/s), or the rate stops short of its final value; or set
            ``learning_rate_by_wall``.
        learning_rate_by_wall: the falling rate runs over whichever ends first, ``total_steps`` or
            ``max_wall_s`` (:class:`sms3d_env.training.schedules.WallAwareLinearSchedule`), so a
            run stopped by its wall limit ends at ``learning_rate_final`` whatever its step rate.
            Needs ``learning_rate_final`` and ``max_wall_s``; makes the rate depend on the
            machine's speed.
        target_kl: PPO stops a round of updates early once the approximate KL divergence from the
            rollout's policy exceeds 1.5 x this (None: no limit, SB3's default).
        posture_target: the env's IK posture (``ControllerConfig.posture_target``),
            ``"estimate"`` (default) or ``"tool"`` (re-solved as the tool turns; lets a policy
            correct a wrong estimate). Saved in ``config.json`` as ``env_options`` so that
            evaluation rebuilds the same env.
        pregrasp_start: the share of training resets that start the arm on the way from home to a
            pre-grasp pose above the estimated target (the env's ``start=PregraspStart(share)``, a
            reverse curriculum); periodic and final evaluations always start at home.
        pregrasp_anneal: lower that share after each rollout to ``pregrasp_start × (1 − s)``,
            ``s`` the success rate of the last 100 training episodes that started at home
            (:mod:`sms3d_env.training.curriculum`); needs ``pregrasp_start`` > 0.
        init_model: a saved model of this algorithm and architecture (``model.zip``, a checkpoint,
            ``best/best_model.zip``) whose weights, and with ``normalize`` observation
            statistics, the run starts from instead of a fresh policy (e.g. a second phase at a
            lower learning rate); ``None``: from scratch. PPO only; ``out`` must be another
            folder. The run's own counters start afresh: its step count, learning-rate schedule
            and ``pregrasp_anneal``'s success window (the share is back at ``pregrasp_start``
            until 10 home-start episodes have ended).
        log_std_init: the Gaussian policy's initial log standard deviation (SB3's default 0: a
            standard deviation of 1 on every normalised command).
        torch_threads: ``torch.set_num_threads`` in the training process. 1 by default: the
            policy's per-step forward pass is tiny, and with the env workers (and anything else)
            on the same cores, 2 intra-op threads made it ~50x slower here (64 ms vs 1.2 ms).
    """

    algo: str = "ppo"
    env_id: str = "SMS3DPick-v1"
    normalize: bool = False
    normalize_reward: bool = False
    scene_pool: int = 0
    pose_error_range_deg: tuple[float, float] | None = None
    total_steps: int = 100_000
    max_wall_s: float | None = None
    n_envs: int = 1
    vec_env: str = "subproc"
    flat_observation: bool = False
    pose_source: str = "oracle"
    pose_error_deg: float = 0.0
    position_noise: float = 0.0
    reward_type: str = "dense"
    num_mushrooms: int = 10
    max_episode_steps: int = 250
    seed: int = 0
    out: str = "runs/policy"
    eval_freq: int = 20_000
    eval_episodes: int = 10
    checkpoint_freq: int = 50_000
    learning_rate: float = 3e-4
    learning_rate_final: float | None = None
    learning_rate_by_wall: bool = False
    target_kl: float | None = None
    posture_target: str = "estimate"
    pregrasp_start: float = 0.0
    pregrasp_anneal: bool = False
    init_model: str | None = None
    batch_size: int = 256
    n_steps: int = 1024
    buffer_size: int = 100_000
    learning_starts: int = 1_000
    gamma: float = 0.99
    net_arch: tuple[int, ...] = (256, 256)
    log_std_init: float = 0.0
    device: str = "cpu"
    torch_threads: int = 1
    verbose: int = 1

    def __post_init__(self) -> None:
        def bad(name: str, why: str) -> ValueError:
            return ValueError(f"TrainConfig.{name} {why}, got {getattr(self, name)!r}")

        if self.algo not in ALGOS:
            raise bad("algo", f"must be one of {ALGOS}")
        if self.pose_source not in POSE_SOURCES:
            raise bad("pose_source", f"must be one of {POSE_SOURCES}")
        if self.reward_type not in REWARD_TYPES:
            raise bad("reward_type", f"must be one of {REWARD_TYPES}")
        if self.env_id not in ENV_IDS:
            raise bad("env_id", f"must be one of {ENV_IDS}")
        if self.env_id in TRAIN_ENV_IDS and self.reward_type != "dense":
            raise bad("reward_type", f"is set by {self.env_id} (staged); leave it at its default")
        if not isinstance(self.normalize, bool):
            raise bad("normalize", "must be a bool")
        if not isinstance(self.normalize_reward, bool):
            raise bad("normalize_reward", "must be a bool")
        if self.normalize_reward and not self.normalize:
            raise bad("normalize_reward", "needs normalize=True (--normalize): the same VecNormalize scales both")
        if self.vec_env not in VEC_ENVS:
            raise bad("vec_env", f"must be one of {VEC_ENVS}")
        if not isinstance(self.flat_observation, bool):
            raise bad("flat_observation", "must be a bool")
        if self.pose_error_range_deg is not None:
            rng = tuple(float(v) for v in self.pose_error_range_deg)
            if len(rng) != 2 or not all(math.isfinite(v) for v in rng) or not 0 <= rng[0] <= rng[1] <= 180:
                raise bad("pose_error_range_deg", "must be (low, high) with 0 <= low <= high <= 180")
            if self.pose_source != "noisy" or self.pose_error_deg or self.position_noise:
                raise bad("pose_error_range_deg", "needs pose_source='noisy', pose_error_deg=0 and position_noise=0")
            object.__setattr__(self, "pose_error_range_deg", rng)
        for name in ("total_steps", "n_envs", "torch_threads", "num_mushrooms", "max_episode_steps", "eval_episodes",
                     "batch_size", "n_steps", "buffer_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "must be an integer >= 1")
        check_bed_size("TrainConfig.num_mushrooms", self.num_mushrooms)
        for name in ("eval_freq", "checkpoint_freq", "learning_starts", "seed", "verbose", "scene_pool"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise bad(name, "must be an integer >= 0")
        for name in ("pose_error_deg", "position_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise bad(name, "must be a finite number >= 0")
        if self.pose_source == "oracle" and (self.pose_error_deg > 0 or self.position_noise > 0):
            raise bad("pose_error_deg", "must be 0 with pose_source='oracle' (use 'noisy')")
        if self.max_wall_s is not None and not (math.isfinite(self.max_wall_s) and self.max_wall_s > 0):
            raise bad("max_wall_s", "must be None or a finite number > 0")
        if not (isinstance(self.learning_rate, (int, float)) and 0 < self.learning_rate < 1):
            raise bad("learning_rate", "must be in (0, 1)")
        if self.learning_rate_final is not None and not (
                isinstance(self.learning_rate_final, (int, float)) and 0 < self.learning_rate_final < 1):
            raise bad("learning_rate_final", "must be None or in (0, 1)")
        if not isinstance(self.learning_rate_by_wall, bool):
            raise bad("learning_rate_by_wall", "must be a bool")
        if self.learning_rate_by_wall and (self.learning_rate_final is None or self.max_wall_s is None):
            raise bad("learning_rate_by_wall", "needs learning_rate_final (the rate to fall to) and "
                                               "max_wall_s (the wall it falls over)")
        if self.target_kl is not None and not (isinstance(self.target_kl, (int, float))
                                               and math.isfinite(self.target_kl) and self.target_kl > 0):
            raise bad("target_kl", "must be None or a finite number > 0")
        if self.target_kl is not None and self.algo != "ppo":
            raise bad("target_kl", "limits PPO's updates; SAC has none to limit (leave it None)")
        if self.posture_target not in POSTURE_TARGETS:
            raise bad("posture_target", f"must be one of {POSTURE_TARGETS}")
        if not (isinstance(self.pregrasp_start, (int, float)) and not isinstance(self.pregrasp_start, bool)
                and 0 <= self.pregrasp_start <= 1):
            raise bad("pregrasp_start", "must be a probability in [0, 1]")
        if not isinstance(self.pregrasp_anneal, bool):
            raise bad("pregrasp_anneal", "must be a bool")
        if self.pregrasp_anneal and not self.pregrasp_start:
            raise bad("pregrasp_anneal", "lowers pregrasp_start, which is 0 (set a share > 0)")
        if self.init_model is not None and not (isinstance(self.init_model, str) and self.init_model):
            raise bad("init_model", "must be None or the path of a saved model")
        if self.init_model is not None and self.algo != "ppo":
            # SB3's set_parameters restores SAC's networks but neither its entropy coefficient nor
            # its replay buffer: the run would not continue the saved one.
            raise bad("init_model", "continues PPO runs only (SAC's entropy coefficient and replay "
                                    "buffer are not restored by loading its weights)")
        if not (0 < self.gamma <= 1):
            raise bad("gamma", "must be in (0, 1]")
        if len(self.net_arch) == 0 or any(int(h) < 1 for h in self.net_arch):
            raise bad("net_arch", "must be a non-empty sequence of positive layer widths")
        if not (isinstance(self.log_std_init, (int, float)) and math.isfinite(self.log_std_init)):
            raise bad("log_std_init", "must be a finite number")
        if not self.out:
            raise bad("out", "must be a non-empty path")
        object.__setattr__(self, "net_arch", tuple(int(h) for h in self.net_arch))

    def env_kwargs(self, pose_source: str | None = None, pose_error_deg: float | None = None,
                   evaluation: bool = False) -> dict[str, Any]:
        """``make_env`` arguments of the run's envs: its training envs, or with ``evaluation`` its
        evaluation env (fresh beds instead of the pool, every episode from home); ``pose_source``
        and ``pose_error_deg`` replace the run's pose condition (its drawn error range too)."""
        from sms3d_env.start_states import PregraspStart

        kw = env_kwargs(self.num_mushrooms, pose_source or self.pose_source,
                        self.pose_error_deg if pose_error_deg is None else pose_error_deg,
                        self.position_noise, self.reward_type, self.max_episode_steps)
        if self.env_id in TRAIN_ENV_IDS:
            kw.pop("reward_type")  # the training id sets its own
        if self.pose_error_range_deg is not None and pose_error_deg is None:
            kw["pose_error_deg"] = self.pose_error_range_deg
        if self.scene_pool and not evaluation:
            kw["scene"] = {"config": kw["scene"], "pool": self.scene_pool}  # SceneSourceConfig's mapping form
        if self.pregrasp_start and not evaluation:
            kw["start"] = PregraspStart(float(self.pregrasp_start))
        kw.update(env_options(self.posture_target))
        return {"env_id": self.env_id, "flat_observation": self.flat_observation, **kw}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """The config a run's ``config.json`` records; ``ValueError`` naming a field that
        :data:`REMOVED_FIELDS` lists when the run set it (the policy would train or act
        otherwise than recorded)."""
        removed = removed_fields_set(d)
        if removed:
            raise ValueError(f"TrainConfig.{removed[0]}={d[removed[0]]!r}: {REMOVED_FIELDS[removed[0]]}")
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        if "net_arch" in kw:
            kw["net_arch"] = tuple(kw["net_arch"])
        return cls(**kw)


def env_kwargs(num_mushrooms: int, pose_source: str, pose_error_deg: float, position_noise: float = 0.0,
               reward_type: str = "dense", max_episode_steps: int = 250) -> dict[str, Any]:
    """``make_env`` arguments for a bed size, a pose condition (``position_noise`` > 0: a
    ``NoisyPose`` with that position noise, m) and a reward."""
    # The mapping form: the env completes its placement (hull-apart where mushrooms collide).
    kw: dict[str, Any] = {
        "scene": {"placement": {"num_mushrooms": int(num_mushrooms)}},
        "pose_source": pose_source, "reward_type": reward_type,
        "max_episode_steps": int(max_episode_steps),
    }
    if pose_source == "noisy" and position_noise:
        from sms3d_env.pose_sources import NoisyPose

        kw["pose_source"] = NoisyPose(float(pose_error_deg), position_std=float(position_noise))
    elif pose_source == "noisy":  # the env refuses pose errors it would ignore
        kw["pose_error_deg"] = float(pose_error_deg)
    return kw
