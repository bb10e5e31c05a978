"""Fixtures of the saved-policy tests: observation statistics written as the package's RL trainer
wrote them beside its models before 0.2.0 (``obs_rms.npz``, which the loader still reads)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sms3d_env.policies.files import ObservationStats


def _write_obs_rms(stats: ObservationStats, path: Path) -> None:
    arrays: dict[str, np.ndarray] = {}
    for k, r in stats.obs.items():
        suffix = "" if k is None else f".{k}"
        arrays.update({f"obs_mean{suffix}": r.mean, f"obs_var{suffix}": r.var, f"obs_count{suffix}": np.float64(r.count)})
    if stats.returns is not None:
        arrays.update(ret_mean=stats.returns.mean, ret_var=stats.returns.var, ret_count=np.float64(stats.returns.count))
    meta = {"format": 1, "keys": None if None in stats.obs else list(stats.obs), "clip_obs": stats.clip_obs,
            "epsilon": stats.epsilon, "norm_reward": stats.norm_reward, "clip_reward": stats.clip_reward,
            "gamma": stats.gamma}
    np.savez(path, meta=np.array(json.dumps(meta)), **arrays)


@pytest.fixture
def write_obs_rms() -> Callable[[ObservationStats, Path], None]:
    """``write_obs_rms(stats, path)``: ``stats`` as an ``obs_rms.npz`` file."""
    return _write_obs_rms
