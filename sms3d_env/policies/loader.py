"""Loading a saved pick policy: ``load_sb3`` / ``load_model`` and where a model's run keeps what
acting needs (``saved_config_path``: its ``config.json``; ``observation_stats_path``: its
observation statistics); ``SHIPPED_POLICY`` is the shipped one. The policy picker that acts with
one is :class:`~sms3d_env.pickers.policy.PolicyActor`.

A model that RL Baselines3 Zoo saved (``python -m rl_zoo3.train``, ``sms3d train-policy`` on an RL
recipe) loads too: its env, options and observation statistics come from the run's ``args.yml``,
``config.yml`` and ``vecnormalize.pkl`` (:mod:`sms3d_env.policies.zoo_runs`).

Trust: loading runs no code from the files. An SB3 model zip holds cloudpickled entries (its
spaces, schedules, policy class); :func:`load_sb3` unpickles none of them but rebuilds each from
trusted data: the policy's description that :func:`~sms3d_env.policies.files.save_model`
writes into the zip (:class:`~sms3d_env.policies.spec.PolicySpec`), or for an RL Zoo run
the env it names, or for a model SB3's own ``save`` wrote the spaces of the registered env that
are its own (``PolicyActor._matched_spec``); the weights are tensors read by
``torch.load(weights_only=True)``, refused when not finite. :func:`load_sb3` refuses a zip
without that description (:func:`~sms3d_env.policies.files.record_policy_spec` adds one to
a file you trust). An env id a file names is one of the package's registered ids or is refused
(:mod:`sms3d_env.policies.envs`); no zip member is inflated past its limit. The observation
statistics beside a model (``obs_rms.npz``) are plain arrays and are read without unpickling; an
SB3 ``vecnormalize.pkl`` beside a model is never loaded, and an RL Zoo run's is decoded by a
restricted reader that builds arrays and inert records only
(:func:`~sms3d_env.policies.zoo_runs.read_vecnormalize`).
"""

from __future__ import annotations

import inspect
import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sms3d_env.policies.files import (
    MAX_MODEL_BYTES,
    OBS_STATS_FILE,
    POLICY_SPEC_MEMBER,
    PolicyFileError,
    check_file_size,
    check_zip_sizes,
    model_member_limit,
    parse_json,
    read_policy_spec,
    read_run_text,
)
from sms3d_env.policies.quoting import clipped, described_error
from sms3d_env.policies.spec import ALGOS, PolicySpec, algorithm_class, policy_kwargs_from_json

#: The shipped pick policy (``model.zip`` with its ``config.json``, ``README.md``, metrics).
SHIPPED_POLICY = Path(__file__).parents[1] / "weights" / "pick_policy" / "model.zip"
#: What SB3's ``VecNormalize.save`` wrote beside models before ``obs_rms.npz``: a pickle, refused.
PICKLED_STATS_FILE = "vecnormalize.pkl"


def _checkpoint_parts(path: Path) -> tuple[str, str] | None:
    """``("ppo", "1400000_steps")`` for SB3 ``CheckpointCallback``'s ``ppo_1400000_steps.zip``."""
    algo, _, rest = path.stem.partition("_")
    return (algo, rest) if rest.endswith("_steps") and rest[: -len("_steps")].isdigit() else None


def checkpoint_steps(path: str | Path) -> int | None:
    """The env steps in a ``CheckpointCallback`` file name (``ppo_1400000_steps.zip`` -> 1400000)."""
    parts = _checkpoint_parts(Path(path))
    return None if parts is None else int(parts[1][: -len("_steps")])


def saved_config_path(model_path: str | Path) -> Path | None:
    """The ``config.json`` of a model's run: beside it, or for a checkpoint in the run's
    ``checkpoints/`` folder the run folder's; ``None`` when there is none."""
    path = Path(model_path)
    for folder in (path.parent, path.parent.parent if _checkpoint_parts(path) else None):
        if folder is not None and (folder / "config.json").is_file():
            return folder / "config.json"
    return None


#: A checkpoint's files by part: (name infix, extension), named as SB3's ``CheckpointCallback``
#: names them (``ppo_obs_rms_1400000_steps.npz`` beside ``ppo_1400000_steps.zip``).
CHECKPOINT_PARTS = {"model": ("", "zip"), "obs_rms": ("obs_rms_", "npz")}


def checkpoint_path(folder: str | Path, algo: str, steps: int, part: str = "model") -> Path:
    """The file of ``part`` (a key of :data:`CHECKPOINT_PARTS`) of the checkpoint at ``steps``."""
    infix, ext = CHECKPOINT_PARTS[part]
    return Path(folder) / f"{algo}_{infix}{steps}_steps.{ext}"


def read_saved_config(path: Path) -> dict[str, Any]:
    """A run's ``config.json`` (``PolicyFileError`` naming it when it is no JSON object)."""
    saved = parse_json(read_run_text(path, "run configuration"), path, "run configuration")
    if not isinstance(saved, dict):
        raise PolicyFileError(path, "not a run configuration (no JSON object)")
    return saved


def observation_stats_path(model_path: str | Path) -> Path | None:
    """The observation statistics saved with a model: ``obs_rms.npz`` beside it, or for a
    checkpoint ``<algo>_<N>_steps.zip`` its ``<algo>_obs_rms_<N>_steps.npz``; ``None`` when
    there are none. ``PolicyFileError`` when there is only SB3's pickle of them
    (``vecnormalize.pkl``, ``<algo>_vecnormalize_<N>_steps.pkl``): unpickling it would run code
    from the file, and acting without the statistics would act on unscaled observations."""
    path = Path(model_path)
    parts = _checkpoint_parts(path)
    candidates = [(path.parent / OBS_STATS_FILE, path.parent / PICKLED_STATS_FILE)]
    if parts is not None:
        algo, steps = parts[0], int(parts[1][: -len("_steps")])
        candidates.append((checkpoint_path(path.parent, algo, steps, "obs_rms"),
                           path.parent / f"{algo}_vecnormalize_{steps}_steps.pkl"))
    for stats, pickled in candidates:
        if stats.is_file():
            return stats
        if pickled.is_file():
            raise PolicyFileError(pickled, f"the observation statistics of {path} are an SB3 pickle, which is not "
                                           "loaded (unpickling runs code from the file); retrain with this version, "
                                           f"which writes {stats.name}")
    return None


def load_model(model_path: str | Path, algo: str | None = None, spec: PolicySpec | None = None) -> Any:
    """Load a saved PPO/SAC model for acting (:func:`load_sb3`, on the CPU); the algorithm comes
    from ``config.json`` beside it if not given, the policy from ``spec`` or else the file's own
    description. A schedule pickled in the file (e.g. a run's
    :class:`~sms3d_env.training.schedules.WallAwareLinearSchedule`) becomes SB3's default: acting
    needs none. A file that cannot be loaded so raises ``PolicyFileError`` naming it."""
    path = Path(model_path)
    if algo is None:
        cfg_file = saved_config_path(path)
        if cfg_file is not None:
            algo = read_saved_config(cfg_file).get("algo")
    if algo is not None and algo not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
    return load_sb3(path, (algo,) if algo else ALGOS, spec)


#: Pickled entries of an SB3 model's ``data`` that need nothing from the file: the last
#: observations and episode records of envs that are gone and ``lr_schedule`` (``_setup_model`` rebuilds it from ``learning_rate``). Loaded as ``None``.
UNUSED_PICKLED_ENTRIES = ("_last_obs", "_last_original_obs", "_last_episode_starts", "ep_info_buffer",
                          "ep_success_buffer", "lr_schedule")
#: Entries SB3's ``save`` leaves out of ``data``: a file holding one was not written by it (and
#: an ``env`` entry would have SB3 build an env by that name).
NEVER_SAVED_ENTRIES = ("env", "device", "policy", "replay_buffer", "rollout_buffer", "_vec_normalize_env",
                       "_logger", "_custom_logger")


def _is_pickled(value: Any) -> bool:
    """SB3's mark of a cloudpickled entry (``save_util.json_to_data`` unpickles exactly these)."""
    return isinstance(value, dict) and ":serialized:" in value


def _trusted_entries(path: Path, data: dict[str, Any], spec: PolicySpec) -> dict[str, Any]:
    """A value for every pickled entry of ``data`` (SB3's ``custom_objects``: SB3 takes these
    instead of unpickling), plus the policy's class, spaces and ``policy_kwargs`` from ``spec``
    whatever the file says: an entry of :data:`UNUSED_PICKLED_ENTRIES` is ``None``, a
    hyperparameter (a schedule, a buffer class) the algorithm's default (acting needs none). ``PolicyFileError`` naming the file for any other pickled entry."""
    never_saved = sorted(set(data) & set(NEVER_SAVED_ENTRIES))
    if never_saved:
        raise PolicyFileError(path, f"holds entries that SB3's save leaves out ({never_saved}): not a model SB3 wrote")
    kwargs = spec.policy_kwargs
    if kwargs is None:
        kwargs = data.get("policy_kwargs", {})
        if _is_pickled(kwargs):
            raise PolicyFileError(path, f"its policy_kwargs are pickled (they name classes) and it holds no "
                                        f"{POLICY_SPEC_MEMBER} to say them")
    try:
        trusted = {"policy_class": spec.policy_class(), "observation_space": spec.observation_space,
                   "action_space": spec.action_space, "policy_kwargs": policy_kwargs_from_json(kwargs)}
    except ValueError as exc:
        raise PolicyFileError(path, str(exc)) from None
    defaults = {name: p.default for name, p in inspect.signature(algorithm_class(spec.algo)).parameters.items()
                if p.default is not inspect.Parameter.empty}
    for key, value in data.items():
        if key in trusted or not _is_pickled(value):
            continue
        if key in UNUSED_PICKLED_ENTRIES:
            trusted[key] = None
        elif key in defaults:
            trusted[key] = defaults[key]
        else:
            raise PolicyFileError(path, f"holds a pickled entry {key!r} ({value.get(':type:')}) that is not rebuilt "
                                        "without unpickling it, and unpickling runs code from the file")
    return trusted


#: What SB3's ``save`` writes into a model's ``pytorch_variables.pth`` (its ``_get_torch_save_params``):
#: SAC's entropy coefficient, for PPO nothing. SB3's ``load`` sets each entry of the file as the
#: model attribute it names, so any other entry would overwrite a part of the model.
TORCH_VARIABLES = {"ppo": (), "sac": ("log_ent_coef", "ent_coef_tensor")}
TORCH_VARIABLES_MEMBER = "pytorch_variables.pth"


@dataclass(frozen=True)
class ModelZip:
    """An SB3 model zip as read once (SB3 loads these bytes, not the file again, which could have
    changed since): its bytes, the archive over them, its ``data`` JSON and its policy
    description (``None`` when it holds no :data:`~sms3d_env.policies.files.POLICY_SPEC_MEMBER`)."""

    raw: bytes
    archive: zipfile.ZipFile
    data: dict[str, Any]
    spec: PolicySpec | None


def read_model_zip(path: Path, names: str = "PPO/SAC") -> ModelZip:
    """The model zip at ``path``, no member inflated past its limit
    (:func:`~sms3d_env.policies.files.check_zip_sizes`); ``PolicyFileError`` naming the file
    when it is no SB3 ``names`` model, is cut short or too large, or its policy description is none."""
    def cut(exc: BaseException) -> PolicyFileError:
        return PolicyFileError(path, f"not a stable-baselines3 {names} model, or cut short ({described_error(exc)}); "
                                     "retrain it or copy it again")

    try:
        check_file_size(path, MAX_MODEL_BYTES, "model")
        raw = path.read_bytes()
        archive = zipfile.ZipFile(io.BytesIO(raw))
    except PolicyFileError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise cut(exc) from None
    check_zip_sizes(path, archive, model_member_limit, MAX_MODEL_BYTES)
    try:
        data = json.loads(archive.read("data"))
        if not isinstance(data, dict):
            raise ValueError("its data is no JSON object")
    except (OSError, KeyError, ValueError, RecursionError, zipfile.BadZipFile, EOFError) as exc:
        raise cut(exc) from None
    try:
        spec = read_policy_spec(archive)
    except (ValueError, zipfile.BadZipFile) as exc:
        raise PolicyFileError(path, f"its {POLICY_SPEC_MEMBER} is no policy description ({exc})") from None
    return ModelZip(raw, archive, data, spec)


def _record_command(path: Path) -> str:
    """A shell command that adds a policy description to ``path``: the path a Python literal
    (``repr``) inside one shell word (``shlex.quote``), so that no quote or ``$(...)`` in a file
    name breaks it or runs when it is pasted."""
    import shlex

    code = f"from sms3d_env.policies.files import record_policy_spec; record_policy_spec({str(path)!r})"
    return f"python -c {shlex.quote(code)}"


def _check_torch_variables(path: Path, archive: zipfile.ZipFile, algo: str) -> None:
    """``PolicyFileError`` naming the file when its :data:`TORCH_VARIABLES_MEMBER` is no mapping
    of finite tensors named in :data:`TORCH_VARIABLES` (read as tensors only, ``weights_only``)."""
    import torch

    if TORCH_VARIABLES_MEMBER not in archive.namelist():
        return
    member = f"{path}: {TORCH_VARIABLES_MEMBER}"
    try:
        variables = torch.load(io.BytesIO(archive.read(TORCH_VARIABLES_MEMBER)), weights_only=True, map_location="cpu")
    except Exception as exc:  # noqa: BLE001  (torch raises UnpicklingError, RuntimeError, ... for bad files)
        raise PolicyFileError(member, f"not readable tensors ({described_error(exc)})") from None
    if not isinstance(variables, dict):
        raise PolicyFileError(member, f"not a mapping of tensors ({type(variables).__name__})")
    unexpected = sorted(str(k) for k in set(variables) - set(TORCH_VARIABLES[algo]))
    if unexpected:
        raise PolicyFileError(member, f"entries {clipped(repr(unexpected))}, which loading would set as attributes "
                                      f"of the model; a {algo.upper()} model's are "
                                      f"{', '.join(TORCH_VARIABLES[algo]) or 'none'}")
    for name, value in variables.items():
        if value is not None and not (isinstance(value, torch.Tensor) and torch.isfinite(value).all()):
            raise PolicyFileError(member, f"{name}: not a tensor of finite values")


def _check_finite_weights(path: Path, model: Any) -> None:
    """``PolicyFileError`` naming the file and parameter when a weight of ``model``'s policy is NaN
    or infinite (the policy would act NaN from its first step)."""
    import torch

    for name, tensor in model.policy.state_dict().items():
        if tensor.is_floating_point() and not torch.isfinite(tensor).all():
            raise PolicyFileError(path, f"policy.pth: {name} holds values that are not finite (NaN or infinite)")


def load_sb3(path: str | Path, algos: tuple[str, ...], spec: PolicySpec | None = None) -> Any:
    """A PPO/SAC model from ``path`` without unpickling anything in it: SB3's ``load`` with every
    pickled entry of the zip's ``data`` given in its place (:func:`_trusted_entries`), the policy
    built from ``spec`` or else the zip's :data:`~sms3d_env.policies.files.POLICY_SPEC_MEMBER`,
    and the weights read by ``torch.load(weights_only=True)``, on the CPU. ``algos``: the
    algorithms the model may be.

    ``PolicyFileError`` naming the file when it is no SB3 model (or cut short, or a member
    inflates past its limit), holds no description of its policy (saved by an earlier version,
    by RL Baselines3 Zoo or SB3 itself: :func:`~sms3d_env.policies.files.record_policy_spec`
    adds one to a file you trust), is of another algorithm, does not load as the policy it
    describes, or holds weights that are not finite or variables that are not its own."""
    path = Path(path)
    names = "/".join(a.upper() for a in algos)
    model_zip = read_model_zip(path, names)
    spec = spec if spec is not None else model_zip.spec
    if spec is None:
        raise PolicyFileError(path, f"holds no {POLICY_SPEC_MEMBER}, the description of its policy that loading it "
                                    "without unpickling needs (it was saved by an earlier version or by other code); "
                                    f"if you trust the file, add one with {_record_command(path)} (that load runs "
                                    "code pickled in it)")
    if spec.algo not in algos:
        raise PolicyFileError(path, f"is a {spec.algo.upper()} model, not {names}")
    trusted = _trusted_entries(path, model_zip.data, spec)
    _check_torch_variables(path, model_zip.archive, spec.algo)
    try:
        model = algorithm_class(spec.algo).load(io.BytesIO(model_zip.raw), device="cpu", custom_objects=trusted)
    except Exception as exc:  # noqa: BLE001  (SB3 raises AssertionError, KeyError, ValueError, RuntimeError, ...)
        raise PolicyFileError(path, f"does not load as the {spec.algo.upper()} {spec.policy} it describes "
                                    f"({described_error(exc)})") from None
    _check_finite_weights(path, model)
    return model
