"""Whole-bed harvesting: ``SMS3DHarvest-v0`` picks one bed clean, mushroom after mushroom, in one
world that lasts the episode, and scores it on yield, damage and mushrooms per hour.

| part | module |
| --- | --- |
| the gym env (``SMS3DHarvestEnv``), its typed errors | :mod:`~sms3d_env.harvest.env` |
| its options (``HarvestConfig``): times, travel, collection point, reward weights | :mod:`~sms3d_env.harvest.config` |
| timed moves above the bed (``Motion``) | :mod:`~sms3d_env.harvest.motion` |
| the scan: the bed as it stands, its detections, the candidates and their features | :mod:`~sms3d_env.harvest.scan` |
| what happened to each mushroom (``BedTally``): yield, damage, missed, per hour | :mod:`~sms3d_env.harvest.scores` |
| the scripted pick orders and re-scan rules (``ScriptedOrder``), ``run_harvest`` | :mod:`~sms3d_env.harvest.orders` |

The names load their module on first access.
"""

from generator.lazy import lazy_exports

_EXPORTS = {
    "SMS3DHarvestEnv": "env", "MaskedActionError": "env", "HarvestConfig": "config",
    "Motion": "motion", "BedTally": "scores", "ScriptedOrder": "orders", "ORDERS": "orders",
    "RESCANS": "orders", "run_harvest": "orders",
}  # fmt: skip

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
