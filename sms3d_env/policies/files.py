"""A saved policy's files: models saved through a temporary file and a rename, each with the
description of its policy that a load without unpickling needs, and the observation statistics
of a normalised run as plain arrays, never a pickle.

Why: SB3's ``model.save`` writes its zip in place, so a run killed while saving left an empty or
cut ``model.zip``; SB3's ``VecNormalize.save`` pickles the whole object, so loading it unpickled
whatever the file held; and SB3's zip pickles the policy class, spaces and schedules.
:func:`save_model` (through :func:`generator.files.write_via_temp`) adds
:data:`POLICY_SPEC_MEMBER` to the zip (:class:`~sms3d_env.policies.spec.PolicySpec`, read back
by :func:`~sms3d_env.policies.loader.load_sb3`); :class:`ObservationStats` holds
``VecNormalize``'s running means and variances (``obs_rms.npz``, what the package's RL trainer
wrote beside its models before 0.2.0), read back with ``allow_pickle=False``.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from generator.files import write_via_temp
from sms3d_env.policies.quoting import clipped, described_error
from sms3d_env.policies.spec import ALGOS, PolicySpec, algorithm_class

#: The most bytes a loader inflates from one member of a model zip: its weights (``.pth``; the
#: shipped policies' are 0.1 MB, a 2x1024 MLP's with its optimiser state ~50 MB) and any other
#: member (``data``, :data:`POLICY_SPEC_MEMBER`: kilobytes). Checked on each member's declared
#: size before it is read: a few megabytes of zip can declare gigabytes.
MAX_WEIGHTS_BYTES = 512 * 2**20
MAX_METADATA_BYTES = 16 * 2**20
#: The most bytes all members of a model zip inflate to together (SB3 reads every ``.pth``), and
#: the most a model file may be on disk.
MAX_MODEL_BYTES = 1024 * 2**20
#: The most bytes of a run's text file read (``config.json``, an RL Zoo run's ``args.yml`` and
#: ``config.yml``, ``summary.json``; these are kilobytes) and of observation statistics
#: (``obs_rms.npz``, an RL Zoo run's ``vecnormalize.pkl``).
MAX_RUN_FILE_BYTES = 1 * 2**20
MAX_STATS_BYTES = MAX_METADATA_BYTES

#: The observation statistics beside a normalised run's ``model.zip`` (and ``best/best_model.zip``).
OBS_STATS_FILE = "obs_rms.npz"
#: The entry of a model zip that describes its policy as JSON (:class:`PolicySpec`); SB3 reads
#: only ``data`` and the ``.pth`` entries, so the zip stays an ordinary SB3 model.
POLICY_SPEC_MEMBER = "sms3d_policy.json"
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


def check_file_size(path: Path, limit: int, what: str) -> None:
    """``PolicyFileError`` naming ``path`` when it is larger than ``limit`` bytes (before it is read)."""
    size = path.stat().st_size
    if size > limit:
        raise PolicyFileError(path, f"{size} bytes, more than any {what} ({limit} bytes at most)")


def read_run_text(path: Path, what: str) -> str:
    """A run's small text file (at most :data:`MAX_RUN_FILE_BYTES`); ``PolicyFileError`` naming it
    when it is larger, unreadable or not UTF-8."""
    try:
        check_file_size(path, MAX_RUN_FILE_BYTES, what)
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise PolicyFileError(path, f"not a readable {what} ({described_error(exc)})") from None


def parse_json(text: str | bytes, path: Path, what: str) -> Any:
    """``text`` as JSON; ``PolicyFileError`` naming ``path`` and ``what`` when it is not JSON,
    not UTF-8, or nested deeper than Python's recursion limit."""
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise PolicyFileError(path, f"not a readable {what} ({described_error(exc)})") from None


def check_zip_sizes(path: Path, archive: zipfile.ZipFile, member_limit: Any, total_limit: int) -> None:
    """``PolicyFileError`` naming ``path`` and the member when a member of ``archive`` declares
    more than ``member_limit(name)`` inflated bytes, or all together more than ``total_limit``.
    Reading a member inflates at most its declared size (``zipfile`` stops there), so checking
    the declarations bounds what reading the archive takes."""
    total = 0
    for info in archive.infolist():
        limit = member_limit(info.filename)
        if info.file_size > limit:
            raise PolicyFileError(path, f"member {clipped(repr(info.filename))} inflates to {info.file_size} bytes, "
                                        f"more than any such member ({limit} bytes at most)")
        total += info.file_size
    if total > total_limit:
        raise PolicyFileError(path, f"its members inflate to {total} bytes, more than {total_limit} in all")


def model_member_limit(name: str) -> int:
    """The most bytes a model zip's member ``name`` may inflate to (:data:`MAX_WEIGHTS_BYTES` for weights)."""
    return MAX_WEIGHTS_BYTES if name.endswith(".pth") else MAX_METADATA_BYTES


def save_model(model: Any, path: str | Path) -> None:
    """An SB3 PPO/SAC model's ``save`` to ``path`` (a ``.zip``) with its :data:`POLICY_SPEC_MEMBER`,
    atomically. ``ValueError`` naming what the spec cannot describe (another algorithm or policy,
    a ``policy_kwargs`` entry that is no JSON data), before anything is written."""
    spec = PolicySpec.of(model)

    def write(tmp: Path) -> None:
        model.save(tmp)
        _add_policy_spec(tmp, spec)

    write_via_temp(path, write)


def _add_policy_spec(zip_path: Path, spec: PolicySpec) -> None:
    """Append :data:`POLICY_SPEC_MEMBER` to the zip at ``zip_path``; its other entries keep their bytes."""
    with zipfile.ZipFile(zip_path, "a", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(POLICY_SPEC_MEMBER, json.dumps(spec.to_json(), indent=1))


def read_policy_spec(archive: zipfile.ZipFile) -> PolicySpec | None:
    """The :class:`PolicySpec` in a model zip, ``None`` when it holds none; ``ValueError`` naming
    the field of one that is not a spec."""
    if POLICY_SPEC_MEMBER not in archive.namelist():
        return None
    try:
        return PolicySpec.from_json(json.loads(archive.read(POLICY_SPEC_MEMBER)))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not JSON ({described_error(exc)})") from None
    except RecursionError:  # json.loads or a space nested in spaces
        raise ValueError("nested deeper than Python's recursion limit") from None


def record_policy_spec(path: str | Path, algo: str | None = None) -> None:
    """Add :data:`POLICY_SPEC_MEMBER` to a model zip saved without one (by an earlier version of
    this package, by RL Baselines3 Zoo, by SB3's own ``model.save``), atomically; every other entry
    keeps its bytes (the weights are not touched). ``algo``: ``"ppo"``/``"sac"``, else each is
    tried. This loads the file with SB3's own loader, which unpickles its entries and so runs any
    code they carry: use it only on files you trust."""
    path = Path(path)
    raw = path.read_bytes()
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            if POLICY_SPEC_MEMBER in archive.namelist():
                raise PolicyFileError(path, f"already holds {POLICY_SPEC_MEMBER}")
    except zipfile.BadZipFile:
        raise PolicyFileError(path, "not a model zip") from None
    failures = []
    for name in (algo,) if algo else ALGOS:
        try:
            model = algorithm_class(name).load(str(path), device="cpu")
            break
        except Exception as exc:  # noqa: BLE001  (SB3 raises AssertionError, KeyError, ValueError, ... for bad files)
            failures.append(f"{name}: {type(exc).__name__}: {exc}")
    else:
        raise PolicyFileError(path, f"SB3 does not load it ({'; '.join(failures)})")
    spec = PolicySpec.of(model)

    def write(tmp: Path) -> None:
        tmp.write_bytes(raw)
        _add_policy_spec(tmp, spec)

    write_via_temp(path, write)


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

    def normalize_obs(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray | dict[str, np.ndarray]:
        """``obs`` standardised and clipped as ``VecNormalize.normalize_obs`` does (float32)."""
        def one(x: np.ndarray, r: RunningStats) -> np.ndarray:
            return np.clip((x - r.mean) / np.sqrt(r.var + self.epsilon), -self.clip_obs, self.clip_obs).astype(np.float32)

        if isinstance(obs, dict):
            return {k: one(v, self.obs[k]) if k in self.obs else v for k, v in obs.items()}
        return one(obs, self.obs[None])

    @classmethod
    def load(cls, path: str | Path) -> ObservationStats:
        """Read an ``obs_rms.npz``, without unpickling anything (``PolicyFileError`` naming
        the file when it is missing, cut or not such a file)."""
        path = Path(path)
        try:
            check_file_size(path, MAX_STATS_BYTES, "observation statistics")
            with zipfile.ZipFile(path) as archive:
                check_zip_sizes(path, archive, lambda _name: MAX_STATS_BYTES, MAX_STATS_BYTES)
            with np.load(path, allow_pickle=False) as z:
                meta = parse_json(str(z["meta"]), path, "meta entry")
                if meta.get("format") != _FORMAT:
                    raise ValueError(f"format {meta.get('format')!r}, expected {_FORMAT}")
                keys = meta["keys"]
                obs = {k: RunningStats(z[f"obs_mean{s}"], z[f"obs_var{s}"], float(z[f"obs_count{s}"]))
                       for k, s in ([(None, "")] if keys is None else [(k, f".{k}") for k in keys])}
                returns = (RunningStats(z["ret_mean"], z["ret_var"], float(z["ret_count"]))
                           if "ret_mean" in z.files else None)
                return cls(obs, float(meta["clip_obs"]), float(meta["epsilon"]), bool(meta["norm_reward"]),
                           returns, float(meta["clip_reward"]), float(meta["gamma"]))
        except PolicyFileError:
            raise
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
            raise PolicyFileError(path, f"not readable observation statistics ({described_error(exc)})") from None

    def check_usable(self, path: str | Path, space: Any) -> None:
        """``PolicyFileError`` naming ``path`` (where these were read) when they cannot normalise
        the observation ``space`` of the policy: statistics of keys or shapes it lacks, a mean or
        variance not finite, a variance below 0 or, with ``epsilon``, 0 (a division by zero), a
        clip or epsilon that is no finite number > 0 (>= 0 for epsilon). Caught here, such
        statistics would otherwise make every action NaN without naming the file."""
        shapes = {k: s.shape for k, s in space.spaces.items()} if hasattr(space, "spaces") else {None: space.shape}
        for key, r in self.obs.items():
            where = "observation" if key is None else f"obs[{clipped(repr(key))}]"
            if key not in shapes or r.mean.shape != shapes[key] or r.var.shape != shapes[key]:
                raise PolicyFileError(path, f"{where}: statistics of shape {r.mean.shape}/{r.var.shape} for a policy "
                                            f"whose observation is {_shapes_text(shapes)}")
            if not (np.all(np.isfinite(r.mean)) and np.all(np.isfinite(r.var)) and math.isfinite(r.count)):
                raise PolicyFileError(path, f"{where}: mean, variance or count not finite")
            if np.any(r.var < 0) or np.any(r.var + self.epsilon <= 0):
                raise PolicyFileError(path, f"{where}: a variance below 0, or 0 with epsilon 0 (a division by zero)")
        if not (math.isfinite(self.epsilon) and self.epsilon >= 0 and math.isfinite(self.clip_obs) and self.clip_obs > 0):
            raise PolicyFileError(path, f"clip_obs {self.clip_obs} and epsilon {self.epsilon}: must be finite, "
                                        "clip_obs > 0 and epsilon >= 0")


def _shapes_text(shapes: dict[str | None, tuple[int, ...]]) -> str:
    return ", ".join(f"{'one array' if k is None else k} {shape}" for k, shape in shapes.items())
