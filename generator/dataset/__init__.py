"""Dataset rendering, writing and reading: RGB-D, masks, COCO, manifest, torch datasets.

Rendering is headless: ``MUJOCO_GL`` defaults to ``egl`` (set by :mod:`generator` before MuJoCo is
imported). For software rendering without EGL use ``MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa``.
"""

from generator.lazy import lazy_exports

#: Public names and the submodules that define them; loaded on first access (PEP 562) so that
#: ``sms3d --help`` and light imports (``generator.dataset.errors``, the ``generate`` parser) do
#: not pay for the renderer's MuJoCo, trimesh and scipy.
_EXPORTS = {
    "backproject": "backproject", "backproject_pixels": "backproject",
    "CorruptFileError": "errors", "DatasetError": "errors", "DatasetWriteError": "errors",
    "ManifestMismatchError": "errors",
    "DatasetOptions": "options", "RealismOptions": "options",
    "generate_dataset": "runner",
}  # fmt: skip

__all__ = sorted(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
