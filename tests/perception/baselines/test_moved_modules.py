"""The baselines' place: the modules that moved under ``perception.baselines`` keep their old
import paths for one release (a dated DeprecationWarning), the shipped pipeline loads none of
the baselines' code, and a missing torchvision names the extra that brings it."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

from perception.deprecation import DEPRECATED_ON, REMOVED_AFTER

PERCEPTION = Path(__file__).resolve().parents[3] / "perception"
SHIM = re.compile(r'moved_module\(__spec__\.name, "([\w.]+)"')


def _shims() -> dict[str, str]:
    """Old module name -> new, for every shim file in the package."""
    found = {}
    for path in sorted(PERCEPTION.rglob("*.py")):
        match = SHIM.search(path.read_text(encoding="utf-8"))
        if match:
            found[".".join(path.relative_to(PERCEPTION.parent).with_suffix("").parts)] = match.group(1)
    return found


def test_the_old_paths_of_the_documented_modules_are_kept() -> None:
    assert {"perception.pose.estimator", "perception.pose.pose_net", "perception.detection.maskrcnn",
            "perception.evaluation.ablation", "perception.evaluation.eval_pose_heldout"} <= set(_shims())


@pytest.mark.parametrize(("old", "new"), sorted(_shims().items()))
def test_an_old_import_path_warns_with_the_dates_and_gives_the_new_module(monkeypatch, old, new) -> None:
    monkeypatch.delitem(sys.modules, old, raising=False)
    expected = f"{old} is deprecated ({DEPRECATED_ON}) and will be removed after {REMOVED_AFTER}: import {new} instead"
    with pytest.warns(DeprecationWarning, match=re.escape(expected)) as caught:
        __import__(old)  # what an ``import`` statement runs
    assert sys.modules[old] is importlib.import_module(new)
    assert caught[0].filename == __file__  # attributed to the importing line, so Python's filter shows it


def test_a_moved_packages_submodules_are_the_new_ones(monkeypatch) -> None:
    for name in [n for n in sys.modules if n.startswith("perception.pose.backbones")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.warns(DeprecationWarning, match="perception.pose.backbones"):
        old = importlib.import_module("perception.pose.backbones.point_transformer")
    from perception.baselines.point_transformer.backbones import point_transformer as new

    assert old is new


def test_an_old_module_still_runs_as_a_script(monkeypatch, capsys) -> None:
    """``python -m perception.evaluation.eval_pose_heldout --help``, run in this process."""
    import runpy

    monkeypatch.delitem(sys.modules, "perception.evaluation.eval_pose_heldout", raising=False)  # not the alias
    monkeypatch.setattr(sys, "argv", ["eval_pose_heldout", "--help"])
    with pytest.warns(DeprecationWarning, match="perception.baselines.point_transformer.eval_heldout instead"), \
            pytest.raises(SystemExit) as exit_:
        runpy.run_module("perception.evaluation.eval_pose_heldout", run_name="__main__", alter_sys=True)
    assert exit_.value.code in (0, None)
    assert "--views" in capsys.readouterr().out


def test_the_shipped_pipeline_loads_no_baseline() -> None:
    code = ("import sys; from perception.pipeline import PosePipeline; import perception.cli_detector, "
            "perception.detection.load; print(sorted(m for m in sys.modules if m.startswith('perception.baselines')))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert result.stdout.strip() == "[]"


def test_mask_rcnn_without_torchvision_names_the_extra(monkeypatch) -> None:
    from perception.baselines.maskrcnn import model

    monkeypatch.setitem(sys.modules, "torchvision", None)  # as if not installed
    with pytest.raises(ImportError, match=re.escape('pip install -e ".[baselines]"')):
        model._import_torchvision()
