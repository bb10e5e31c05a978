"""Stage 1 by name: ``load_detector("shipped" | "oracle" | PATH)``, the one place that decides
which detector a command, the pipeline or the environment uses.

- ``"shipped"`` (the default everywhere): the RGB-D segmenter shipped in
  ``perception/weights/segmenter/`` (no download; its README gives the recipe and metrics);
- ``"oracle"``: MuJoCo's segmentation render (exact masks, for ablations) — returned as ``None``,
  the pipeline's "masks are passed in" mode;
- a path: a checkpoint of ``sms3d train-segmenter`` or of ``sms3d train-detector`` (Mask R-CNN),
  told apart by the format stored in it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from perception.detection.detector import Detector

SHIPPED_SEGMENTER = Path(__file__).resolve().parents[1] / "weights" / "segmenter" / "segmenter.pt"
SPECS = ("shipped", "oracle")


def describe_detector(spec: str | None) -> str:
    """What ``spec`` names, for the ``masks: <source>`` line of reports."""
    if spec in (None, "oracle"):
        return "oracle (MuJoCo segmentation render)"
    if spec == "shipped":
        return f"shipped RGB-D segmenter ({SHIPPED_SEGMENTER.parent.name}/{SHIPPED_SEGMENTER.name})"
    return f"checkpoint {spec}"


def load_detector(spec: str | None = "shipped", threads: int | None = None, **overrides: Any) -> Detector | None:
    """The detector ``spec`` names (see the module doc); ``None`` for ``"oracle"``.

    ``overrides`` are decoding settings of the checkpoint's config (e.g. ``score_threshold``).
    A missing or unreadable file raises ``FileNotFoundError`` / ``CheckpointFormatError`` naming it.
    """
    if spec in (None, "oracle"):
        return None
    from perception.detection.rgbd_segmenter import load_segmenter
    from perception.errors import CheckpointFormatError

    path = SHIPPED_SEGMENTER if spec == "shipped" else Path(spec)
    if not path.is_file():
        hint = " (the shipped weights are missing: reinstall the package)" if spec == "shipped" else ""
        raise FileNotFoundError(f"{path}: no such detector checkpoint{hint}; use 'shipped', 'oracle' or a path")
    try:
        return load_segmenter(path, threads=threads, **overrides)
    except CheckpointFormatError:  # not a segmenter: Mask R-CNN's reader names what else it is
        pass
    from perception.baselines.maskrcnn.model import MaskRCNNDetector

    return MaskRCNNDetector.from_checkpoint(path, **overrides)
