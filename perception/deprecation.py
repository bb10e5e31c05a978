"""One-release deprecations: what moved or goes away warns, with the date it was deprecated and
the date after which it is removed, and names what to use instead (as trimesh does).

A moved module leaves a shim at its old path that calls :func:`moved_module`: importing the old
path warns and gives the new module itself (``sys.modules`` maps the old name, and those of a
moved package's submodules, to the new ones), so ``from old.path import name`` and
``isinstance`` checks keep working for one release, and ``python -m old.path`` still runs the
new module's ``main``.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from types import ModuleType

#: When the baselines moved under ``perception.baselines`` and ``sms3d train-pose`` lost its
#: hyperparameter flags.
DEPRECATED_ON = "2026-12-06"
#: One release later: the old paths and flags are removed after this date.
REMOVED_AFTER = "2027-06-06"


def deprecation_message(what: str, instead: str) -> str:
    """``what`` is deprecated since :data:`DEPRECATED_ON`, removed after :data:`REMOVED_AFTER`;
    ``instead`` says what to use."""
    return f"{what} is deprecated ({DEPRECATED_ON}) and will be removed after {REMOVED_AFTER}: {instead}"


def moved_module(old: str, new: str, run_main: bool = False) -> ModuleType:
    """Warn that module ``old`` moved to ``new`` and make ``old`` an alias of it.

    Called by the shim at ``old``'s path with ``old = __spec__.name``. With ``run_main`` (the
    shim was run as ``python -m old``), runs ``new``'s ``main()`` and exits with its code.
    """
    message = deprecation_message(old, f"import {new} instead")
    # Attributed to the line that imported the shim (1: here, 2: the shim, 3: its importer; the
    # warnings module skips the import machinery's frames), or to the shim itself when it runs
    # as ``__main__``: Python's default filter shows a DeprecationWarning raised from __main__.
    warnings.warn(message, DeprecationWarning, stacklevel=2 if run_main else 3)
    module = importlib.import_module(new)
    if run_main:
        raise SystemExit(module.main())
    sys.modules[old] = module
    for name in [n for n in sys.modules if n.startswith(new + ".")]:  # a package's loaded submodules
        sys.modules[old + name[len(new):]] = sys.modules[name]
    return module

