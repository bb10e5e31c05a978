"""Pickers: what turns an observation into an action.

| picker | module |
| --- | --- |
| the scripted pose-aware pickers (``ScriptedPicker``; ``HandPicker`` for the hand) | :mod:`~sms3d_env.pickers.scripted` |
| one seeded episode of any picker as the study's row (``run_episode``) | :mod:`~sms3d_env.pickers.episode` |
| a saved SB3 policy as a picker (``PolicyActor``; its files: :mod:`sms3d_env.policies`) | :mod:`~sms3d_env.pickers.policy` |
| pickers by name for the study and benchmarks (``parse_picker``, ``make_picker_env``) | :mod:`~sms3d_env.pickers.registry` |

Learned pickers are trained by :mod:`sms3d_env.training`; nothing here imports it.
The names load their module on first access.
"""

from generator.lazy import lazy_exports

_EXPORTS = {
    "HandPicker": "scripted", "ScriptedPicker": "scripted", "run_episode": "episode", "PolicyActor": "policy",
    "PICKER_KINDS": "registry", "PickerSpec": "registry", "make_picker_env": "registry",
    "parse_picker": "registry",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
