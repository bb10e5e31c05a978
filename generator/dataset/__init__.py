"""Dataset rendering, writing and reading: RGB-D, masks, COCO, manifest, torch datasets.

Rendering is headless: ``MUJOCO_GL`` defaults to ``egl`` here (set before MuJoCo is imported).
For software rendering without EGL use ``MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa``.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # must precede the first import of mujoco

# ruff: noqa: E402

from generator.dataset.backproject import backproject, backproject_pixels
from generator.dataset.errors import (
    CorruptFileError,
    DatasetError,
    DatasetWriteError,
    ManifestMismatchError,
)
from generator.dataset.options import DatasetOptions, RealismOptions
from generator.dataset.runner import generate_dataset

__all__ = [
    "CorruptFileError", "DatasetError", "DatasetOptions", "DatasetWriteError", "ManifestMismatchError",
    "RealismOptions", "backproject", "backproject_pixels", "generate_dataset",
]
