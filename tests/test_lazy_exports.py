"""Lazy package exports: names load their submodule on first access and stay cached."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from generator.lazy import lazy_exports


def test_a_name_loads_its_submodule_once_and_unknown_names_fail() -> None:
    namespace: dict = {}
    getattr_, dir_ = lazy_exports("generator", {"SceneConfig": "config"}, namespace)
    from generator.config import SceneConfig

    assert getattr_("SceneConfig") is SceneConfig and namespace["SceneConfig"] is SceneConfig
    assert "SceneConfig" in dir_()
    with pytest.raises(AttributeError, match="'generator' has no attribute 'Nope'"):
        getattr_("Nope")


@pytest.mark.parametrize("package", ["generator", "sms3d_env", "sms3d_env.pickers", "sms3d_env.policies", "sms3d_env.pose_sources",
                                     "sms3d_env.tools", "sms3d_env.training"])
def test_packages_export_every_public_name(package: str) -> None:
    module = importlib.import_module(package)
    for name in module.__all__:
        assert getattr(module, name) is not None, name
    assert set(module.__all__) <= set(dir(module))


def test_importing_the_packages_loads_no_heavy_module() -> None:
    code = ("import sys, generator, generator.dataset, sms3d_env, sms3d_env.pickers, sms3d_env.policies, sms3d_env.training, "
            "sms3d_env.study; print(sorted({'mujoco', 'trimesh', 'torch', 'mink'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
