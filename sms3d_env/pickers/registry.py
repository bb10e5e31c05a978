"""Pickers by name, for the study and the benchmarks: ``"scripted"`` or ``"policy[:PATH]"`` (a
saved SB3 policy; no path: the shipped one). ``"policy@ENV_ID:PATH"`` names the
env of a model whose files do not say it (one saved by SB3's own ``save``), as ``eval-policy
--env-id`` does.

A learned picker runs on the env id and options it was trained with (the ``config.json`` of its
run: beside the model or, for a checkpoint, in its run folder), so ``make_picker_env`` builds
that env; every reset draws the same scene, target and pose estimate from the same seed
whatever the picker (the options change the episode, not its draw), which keeps the study's
design paired.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

PICKER_KINDS = ("scripted", "policy")
#: Picker kinds removed from the package, refused by name with why: ``"residual[:PATH]"`` ran a
#: residual policy on top of the scripted picker (no path: the shipped descend trigger).
REMOVED_PICKER_KINDS = {
    "residual": "residual PPO and the learned descend trigger on top of the scripted picker were removed in "
                "0.2.0: residual PPO never beat the scripted picker and the trigger's gain was gone on v1 "
                "(McNemar p >= 0.25; docs/results-training.md, \"What did not widen it\"; CHANGELOG.md; git "
                "history keeps them); use scripted or policy[:PATH]",
}
#: What figures and tables call a picker by its ``PickerSpec.label``: the shipped ones by the
#: names the documentation uses; a saved model keeps its label (kind and run folder).
PICKER_NAMES = {"scripted": "scripted picker", "policy": "shipped policy"}


#: The env the scripted picker acts in (a learned picker acts in the one it was trained on).
SCRIPTED_ENV_ID = "SMS3DPick-v2"

@dataclass(frozen=True)
class PickerSpec:
    """``kind`` in ``PICKER_KINDS``; ``path`` the model (None: the shipped policy); ``env_id`` its
    env where its files do not say it."""

    kind: str = "scripted"
    path: str | None = None
    env_id: str | None = None

    @property
    def label(self) -> str:
        if self.kind == "scripted":
            return "scripted"
        return f"{self.kind}:{Path(self.path).parent.name}" if self.path else self.kind

    @property
    def model_path(self) -> Path | None:
        """The model a learned picker loads (the shipped one of its kind without a path); None
        for the scripted picker."""
        from sms3d_env.policies.loader import SHIPPED_POLICY

        if self.kind == "scripted":
            return None
        return Path(self.path) if self.path else SHIPPED_POLICY


def picker_name(label: str) -> str:
    """The name a figure or table gives the picker of a sweep row's ``picker`` label."""
    return PICKER_NAMES.get(label, label)


def parse_picker(text: str) -> PickerSpec:
    """``"scripted"`` or ``"policy[:PATH]"`` (ValueError naming the picker otherwise, and for a
    removed kind why it was removed; a missing model file raises FileNotFoundError)."""
    from sms3d_env.policies.spec import package_env_ids

    name, _, path = str(text).partition(":")
    kind, at, env_id = name.partition("@")
    if kind in REMOVED_PICKER_KINDS:
        raise ValueError(f"picker {text!r}: {REMOVED_PICKER_KINDS[kind]}")
    if kind not in PICKER_KINDS:
        raise ValueError(f"picker must be one of {PICKER_KINDS} (policy with an optional :PATH), "
                         f"got {text!r}")
    if kind == "scripted" and path:
        raise ValueError(f"the scripted picker takes no model path, got {text!r}")
    if at and not (kind == "policy" and path and env_id in package_env_ids()):
        raise ValueError(f"policy@ENV_ID:PATH names the env of a saved policy, ENV_ID one of "
                         f"{', '.join(package_env_ids())}; got {text!r}")
    if path and not Path(path).is_file():
        raise FileNotFoundError(f"picker model not found: {path}")
    return PickerSpec(kind, path or None, env_id or None)


def make_picker_env(spec: PickerSpec, **env_kwargs: Any) -> tuple[Any, Any]:
    """``(env, picker)``: the env the picker was trained on (``env_kwargs`` added) and the picker,
    a callable ``obs -> action``. A learned picker sets torch to one intra-op thread."""
    if spec.kind == "scripted":
        import gymnasium as gym

        import sms3d_env  # noqa: F401  (registers the env ids)
        from sms3d_env.pickers.scripted import ScriptedPicker

        env = gym.make(SCRIPTED_ENV_ID, **env_kwargs)
        return env, ScriptedPicker.for_env(env)
    import torch

    from sms3d_env.pickers.policy import PolicyActor

    # Per-step inference of a small MLP: more intra-op threads only add overhead, and the
    # study's worker processes would oversubscribe the cores (2 workers x 2 threads on 2 cores
    # ran the policy sweep ~2.5x slower).
    torch.set_num_threads(1)
    actor = PolicyActor(spec.model_path, env_id=spec.env_id)
    env = actor.make_env(**env_kwargs)
    return env, actor
