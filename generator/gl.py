"""Opening MuJoCo's off-screen renderer safely next to PyTorch.

PyPI's standard torch build pulls in Triton, whose LLVM-based extension crashes the process
(segmentation fault) when it is first imported while a software-EGL (Mesa llvmpipe) context is
current, which happens when training starts after an environment or a view renderer is open:
``torch.optim.Adam`` imports it lazily. Importing Triton before the first context avoids the clash.
"""

from __future__ import annotations

import importlib.util

import mujoco


def _preload_triton() -> None:
    if importlib.util.find_spec("triton") is not None:
        import triton  # noqa: F401


def open_renderer(model: mujoco.MjModel, height: int, width: int, **kwargs) -> mujoco.Renderer:
    """``mujoco.Renderer(model, height, width, **kwargs)``, with Triton loaded first if installed."""
    _preload_triton()
    return mujoco.Renderer(model, height, width, **kwargs)
