"""The env arguments that training's recipes and commands build their envs from: one builder,
:func:`env_kwargs`, for the behaviour-cloning recipe's demonstrations and DAgger rounds,
``sms3d record-demos`` and ``sms3d eval-policy``. (An RL recipe writes its ``env_kwargs`` out in
full; RL Zoo hands them to ``gym.make`` as they stand.)"""

from __future__ import annotations

from typing import Any

#: The id the behaviour-cloning recipe records, clones and evaluates on.
TRAIN_ENV_ID = "SMS3DPickTrain-v2"
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


def env_kwargs(num_mushrooms: int, pose_error_deg: float = 0.0,
               pose_error_range_deg: tuple[float, float] | None = None,
               posture_target: str = "estimate") -> dict[str, Any]:
    """``gym.make`` arguments for a bed size, a pose error (0: exact poses; or drawn per episode in
    ``pose_error_range_deg``) and the IK posture option; JSON, so that an env spec made with them
    rebuilds the env (a Minari dataset's ``recover_environment``). The mapping form of the scene:
    the env completes its placement."""
    kw: dict[str, Any] = {"scene": {"placement": {"num_mushrooms": int(num_mushrooms)}},
                          **env_options(posture_target)}
    if pose_error_range_deg is not None:
        kw.update(pose_source="noisy", pose_error_deg=tuple(float(v) for v in pose_error_range_deg))
    elif pose_error_deg > 0:
        kw.update(pose_source="noisy", pose_error_deg=float(pose_error_deg))
    return kw
