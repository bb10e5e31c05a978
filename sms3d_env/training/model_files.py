"""The files of a policy run on disk: models saved through a temporary file and a rename, and the
observation statistics of a normalised run as plain arrays (``obs_rms.npz``), never a pickle.

Why: SB3's ``model.save`` writes its zip in place, so a run killed while saving left an empty or
cut ``model.zip`` or checkpoint; and SB3's ``VecNormalize.save`` pickles the whole wrapper, so
loading the statistics unpickled whatever the file held. :func:`save_model` (through
:func:`generator.files.write_via_temp`) serves every save of a run (final model, best model,
checkpoints); :class:`ObservationStats` holds ``VecNormalize``'s running means and variances,
read back with ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_via_temp

#: The observation statistics beside a normalised run's ``model.zip`` (and ``best/best_model.zip``).
OBS_STATS_FILE = "obs_rms.npz"
_FORMAT = 1


class PolicyFileError(ValueError):
    """A saved policy's file (model, ``config.json``, observation statistics) that cannot be used;
    the message names the file and why."""

    def __init__(self, path: str | Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = Path(path)
        self.message = message

    def __reduce__(self):  # picklable across the study's worker processes
        return (type(self), (self.path, self.message))


def save_model(model: Any, path: str | Path) -> None:
    """An SB3 model's ``save`` to ``path`` (a ``.zip``), atomically."""
    write_via_temp(path, model.save)


@dataclass(frozen=True)
class RunningStats:
    """One ``RunningMeanStd``: the running mean, variance and sample count."""

    mean: np.ndarray
    var: np.ndarray
    count: float


@dataclass(frozen=True)
class ObservationStats:
    """What ``VecNormalize`` normalises with, as arrays: ``obs`` per observation key (the key
    ``None`` for a flat observation), the clip and epsilon, and with ``norm_reward`` the
    discounted return's statistics (``returns``) and their clip and discount."""

    obs: dict[str | None, RunningStats]
    clip_obs: float
    epsilon: float
    norm_reward: bool = False
    returns: RunningStats | None = None
    clip_reward: float = 10.0
    gamma: float = 0.99

    @classmethod
    def of(cls, venv: Any) -> ObservationStats:
        """The statistics of a ``VecNormalize`` now (copies)."""
        rms = venv.obs_rms if isinstance(venv.obs_rms, dict) else {None: venv.obs_rms}
        return cls({k: _copy(r) for k, r in rms.items()}, float(venv.clip_obs), float(venv.epsilon),
                   bool(venv.norm_reward), _copy(venv.ret_rms), float(venv.clip_reward), float(venv.gamma))

    def apply_to(self, venv: Any) -> None:
        """Set a ``VecNormalize``'s statistics to these (a resumed run's, or an ``init_model``'s);
        ``ValueError`` when its observation has other keys or shapes."""
        rms = venv.obs_rms if isinstance(venv.obs_rms, dict) else {None: venv.obs_rms}
        if set(rms) != set(self.obs) or any(rms[k].mean.shape != self.obs[k].mean.shape for k in rms):
            raise ValueError(f"observation statistics of {_layout(self.obs)} do not fit the env's {_layout(rms)}")
        for k, r in rms.items():
            r.mean, r.var, r.count = self.obs[k].mean.copy(), self.obs[k].var.copy(), self.obs[k].count
        if self.returns is not None:
            venv.ret_rms.mean, venv.ret_rms.var = self.returns.mean.copy(), self.returns.var.copy()
            venv.ret_rms.count = self.returns.count

    def normalize_obs(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray | dict[str, np.ndarray]:
        """``obs`` standardised and clipped as ``VecNormalize.normalize_obs`` does (float32)."""
        def one(x: np.ndarray, r: RunningStats) -> np.ndarray:
            return np.clip((x - r.mean) / np.sqrt(r.var + self.epsilon), -self.clip_obs, self.clip_obs).astype(np.float32)

        if isinstance(obs, dict):
            return {k: one(v, self.obs[k]) if k in self.obs else v for k, v in obs.items()}
        return one(obs, self.obs[None])

    def save(self, path: str | Path) -> None:
        """Write to ``path`` (``.npz``: arrays, and the rest as JSON text), atomically."""
        arrays: dict[str, np.ndarray] = {}
        for k, r in self.obs.items():
            suffix = "" if k is None else f".{k}"
            arrays.update({f"obs_mean{suffix}": r.mean, f"obs_var{suffix}": r.var,
                           f"obs_count{suffix}": np.float64(r.count)})
        if self.returns is not None:
            arrays.update(ret_mean=self.returns.mean, ret_var=self.returns.var, ret_count=np.float64(self.returns.count))
        meta = {"format": _FORMAT, "keys": None if None in self.obs else list(self.obs), "clip_obs": self.clip_obs,
                "epsilon": self.epsilon, "norm_reward": self.norm_reward, "clip_reward": self.clip_reward,
                "gamma": self.gamma}
        write_via_temp(path, lambda tmp: np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays))

    @classmethod
    def load(cls, path: str | Path) -> ObservationStats:
        """Read what :meth:`save` wrote, without unpickling anything (``PolicyFileError`` naming
        the file when it is missing, cut or not such a file)."""
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                if meta.get("format") != _FORMAT:
                    raise ValueError(f"format {meta.get('format')!r}, expected {_FORMAT}")
                keys = meta["keys"]
                obs = {k: RunningStats(z[f"obs_mean{s}"], z[f"obs_var{s}"], float(z[f"obs_count{s}"]))
                       for k, s in ([(None, "")] if keys is None else [(k, f".{k}") for k in keys])}
                returns = (RunningStats(z["ret_mean"], z["ret_var"], float(z["ret_count"]))
                           if "ret_mean" in z.files else None)
                return cls(obs, float(meta["clip_obs"]), float(meta["epsilon"]), bool(meta["norm_reward"]),
                           returns, float(meta["clip_reward"]), float(meta["gamma"]))
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
            raise PolicyFileError(path, f"not readable observation statistics ({type(exc).__name__}: {exc})") from None


def _copy(r: Any) -> RunningStats:
    return RunningStats(np.array(r.mean, np.float64), np.array(r.var, np.float64), float(r.count))


def _layout(rms: dict[str | None, Any]) -> str:
    return ", ".join(f"{'observation' if k is None else k} {tuple(r.mean.shape)}" for k, r in sorted(
        rms.items(), key=lambda kv: str(kv[0])))


def run_settings(config: dict[str, Any]) -> dict[str, Any]:
    """What a run's folder records as its settings (:func:`generator.run_folder.open_run_folder`):
    its configuration but ``out``, the folder itself (a run moved elsewhere resumes there)."""
    return {k: v for k, v in config.items() if k != "out"}


def finished_run(folder: Path, **expected: Any) -> dict[str, Any] | None:
    """The summary of the finished run in ``folder``, after saying so: its ``summary.json`` (the
    last file a run writes), when that holds the ``expected`` values; None otherwise."""
    path = folder / "summary.json"
    if not path.is_file():
        return None
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(summary, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as exc:
        raise PolicyFileError(path, f"unreadable run summary ({exc}); --overwrite to start the run anew") from None
    if any(summary.get(k) != v for k, v in expected.items()):
        return None
    print(f"{folder} is complete ({path.name}); nothing to do (--overwrite to start it anew)")
    return summary
