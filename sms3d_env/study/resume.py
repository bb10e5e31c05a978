"""A sweep folder's settings and parts: what ``sweep_config.json`` records (the config, the pose
weights behind perception parts, a learned picker's files), the check that refuses to resume
parts made with other settings, and reading the parts back (``load_rows``)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from generator.dataset.errors import CorruptFileError
from sms3d_env.pickers.registry import SCRIPTED_ENV_ID
from sms3d_env.study.plan import SweepConfig

# Settings that change what a part file holds without changing its name: a folder's parts can
# only be reused by a sweep that agrees on them (errors, episodes and variants may grow).
RESUME_KEYS = ("env_id", "seed", "chunk", "env_kwargs", "picker", "picker_sha256", "position_along_axis")
# The same for the perception parts alone (the pose-error parts never see a camera), plus the
# digest of the pose weights when the sweep asks for perception episodes.
PERCEPTION_RESUME_KEYS = ("perception_detector", "perception_realism")
# The env generation a sweep's rows come from: parts made on another (v0's ghost Jaco) are not reused.
SWEEP_ENV_ID = SCRIPTED_ENV_ID
# What a folder recorded before a key existed (its parts were made with this value).
_RESUME_DEFAULTS = {"env_id": "SMS3DPick-v0", "picker": "scripted", "picker_sha256": None, "position_along_axis": False,
                    "perception_realism": False}


def _pose_weights_digest(config: SweepConfig) -> str:
    """SHA-256 (16 hex digits) of the weights the perception episodes use: the shipped axis
    CNN, and the stage-1 detector's file unless it is the oracle."""
    import hashlib

    from perception.detection.load import SHIPPED_SEGMENTER
    from perception.pose.axis_cnn import SHIPPED_AXIS_CNN

    digest = hashlib.sha256(SHIPPED_AXIS_CNN.read_bytes())
    if config.perception_detector != "oracle":
        detector = SHIPPED_SEGMENTER if config.perception_detector == "shipped" else Path(config.perception_detector)
        if detector.is_file():  # a missing file is named when the episodes load it
            digest.update(detector.read_bytes())
    return digest.hexdigest()[:16]


def _picker_digests(config: SweepConfig) -> dict[str, str] | None:
    """SHA-256 (16 hex digits) of each file a learned picker loads, by path: its model, and its
    run's ``config.json`` (the env options it acts in) and observation statistics where it has
    them; None for the scripted picker."""
    import hashlib

    from sms3d_env.pickers.registry import parse_picker
    from sms3d_env.policies.loader import observation_stats_path, saved_config_path

    model = parse_picker(config.picker).model_path
    if model is None:
        return None
    files = [f for f in (model, saved_config_path(model), observation_stats_path(model)) if f is not None]
    return {str(f): hashlib.sha256(f.read_bytes()).hexdigest()[:16] for f in files}


def settings(config: SweepConfig) -> dict[str, Any]:
    """What ``sweep_config.json`` records: the config, the pose weights behind perception parts
    and the learned picker's files."""
    digest = _pose_weights_digest(config) if config.perception_episodes else None
    return json.loads(json.dumps({**dataclasses.asdict(config), "env_id": SWEEP_ENV_ID, "pose_weights_sha256": digest,
                                  "picker_sha256": _picker_digests(config)}, default=str))


def read_json(path: Path, remedy: str) -> Any:
    """``path``'s JSON, or :class:`CorruptFileError` naming the file (truncated, not text)."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError
        raise CorruptFileError(path, f"not readable JSON ({exc}); {remedy}") from exc


def _difference(key: str, recorded: Any, requested: Any) -> str:
    """A resume setting that differs, as the refusal names it: the learned picker's files by path."""
    if key != "picker_sha256":
        return f"{key}: folder has {recorded!r}, requested {requested!r}"
    # Records from before the config.json was hashed hold the model's digest alone (a string).
    old, new = (d if isinstance(d, dict) else {} for d in (recorded, requested))
    changed = sorted(f for f in old.keys() | new.keys() if old.get(f) != new.get(f))
    return f"picker files changed since the parts were made: {', '.join(changed)}"


def check_resumable(path: Path, requested: dict[str, Any]) -> None:
    # Only parts could be reused with the wrong settings: a folder without any (its sweep
    # stopped before a task finished) takes the new settings.
    if not any(path.parent.glob("parts/*.json")):
        return
    if not path.is_file():
        # Parts arrive without their settings when copied from another sweep; reusing them
        # unchecked could mix episodes of other physics, pickers or pose weights.
        raise ValueError(f"{path.parent} holds parts but no {path.name}, so their settings are unknown; copy the "
                         f"{path.name} of the sweep that made them beside them, or use another --out")
    stored = read_json(path, "remove the folder or use another --out")
    if "env_kwargs" in stored:  # a folder of an earlier version names the env options as that version did
        from sms3d_env.env_args import translate_legacy_options

        stored["env_kwargs"] = translate_legacy_options(stored["env_kwargs"])
    old_size = stored.get("num_mushrooms")
    if isinstance(old_size, int) and old_size != 25:
        # Before bed sizes were axes, a part's name did not say its size (25 is named by none).
        raise ValueError(f"{path.parent} holds a sweep of {old_size}-mushroom beds made before bed "
                         f"sizes were named in part files; use another --out")
    keys = list(RESUME_KEYS)
    if any(path.parent.glob("parts/*_perception_*.json")):
        keys += PERCEPTION_RESUME_KEYS
        if requested["pose_weights_sha256"] is not None:
            keys.append("pose_weights_sha256")  # perception parts made with other weights are stale
    differ = {k: (stored.get(k, _RESUME_DEFAULTS.get(k)), requested[k]) for k in keys
              if stored.get(k, _RESUME_DEFAULTS.get(k)) != requested[k]}
    if differ:
        details = ", ".join(_difference(k, a, b) for k, (a, b) in differ.items())
        raise ValueError(f"{path.parent} holds a sweep with other settings ({details}); use another --out")


def load_rows(folder: str | Path) -> list[dict[str, Any]]:
    """Every row of a sweep folder's part files (any order of tasks; sorted by name)."""
    parts = sorted(Path(folder, "parts").glob("*.json"))
    if not parts:
        raise FileNotFoundError(f"{folder} holds no sweep parts (run sms3d sweep --out {folder} first)")
    rows: list[dict[str, Any]] = []
    for path in parts:
        rows.extend(read_json(path, "delete it and run the sweep again to redo that task"))
    return rows
