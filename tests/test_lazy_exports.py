"""Lazy package exports: names load their submodule on first access and stay cached."""

from __future__ import annotations

import subprocess
import sys

import pytest

import generator
from generator.lazy import lazy_exports


def test_a_name_loads_its_submodule_once_and_unknown_names_fail() -> None:
    namespace: dict = {}
    getattr_, dir_ = lazy_exports("generator", {"SceneConfig": "config"}, namespace)
    from generator.config import SceneConfig

    assert getattr_("SceneConfig") is SceneConfig and namespace["SceneConfig"] is SceneConfig
    assert "SceneConfig" in dir_()
    with pytest.raises(AttributeError, match="'generator' has no attribute 'Nope'"):
        getattr_("Nope")


def test_packages_export_every_public_name() -> None:
    for name in generator.__all__:
        assert getattr(generator, name) is not None
    assert set(generator.__all__) <= set(dir(generator))


def test_importing_the_packages_loads_no_heavy_module() -> None:
    code = "import sys, generator, generator.dataset, sms3d_env; print(sorted({'mujoco', 'trimesh', 'torch', 'mink'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
