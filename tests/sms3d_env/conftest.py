"""Fixtures of the env core's unit tests: one small generated bed, and worlds built on it without
the gym env (a compile per robot, then a 3 ms copy per world)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import pytest

import generator
from sms3d_env.controller import ControllerConfig
from sms3d_env.robot import RobotSpec
from sms3d_env.world import World, build_world


def _can_touch(model: mujoco.MjModel, a: int, b: int) -> bool:
    contype, conaffinity = model.geom_contype, model.geom_conaffinity
    return bool(contype[a] & conaffinity[b] or contype[b] & conaffinity[a])


@pytest.fixture(scope="session")
def can_touch() -> Callable[[mujoco.MjModel, int, int], bool]:
    """``can_touch(model, a, b)``: MuJoCo's contact filter between geoms ``a`` and ``b`` (either's
    contype in the other's conaffinity)."""
    return _can_touch


@pytest.fixture(scope="session")
def bed() -> generator.Scene:
    """A generated bed of 6 mushrooms (seed 0)."""
    return generator.generate_scene(generator.SceneConfig().replace(placement__num_mushrooms=6), seed=0)


@pytest.fixture(scope="session")
def upright(bed) -> int:
    """The bed's most upright mushroom: its cap top faces a tool pointing straight down."""
    return int(np.argmax([inst.stem_axis[2] for inst in bed.instances]))


@pytest.fixture(scope="session")
def make_world(bed, upright) -> Callable[..., World]:
    """``make_world(robot, target=upright, free_radius=None) -> World``: a new world on ``bed``
    with the arm at ``robot.home_q`` (commanded there too) and forward dynamics done, at the
    env's physics step. Each call gets its own model copy, so a test may change it."""
    models: dict[Any, mujoco.MjModel] = {}
    timestep = ControllerConfig().control_dt / ControllerConfig().substeps

    def make(robot: RobotSpec, target: int = upright, free_radius: float | None = None) -> World:
        world = build_world(bed, target, robot, free_radius, timestep, models, (robot, target, free_radius))
        world.data.qpos[world.arm_qadr] = robot.home_q
        world.data.ctrl[:len(robot.joints)] = robot.home_q
        mujoco.mj_forward(world.model, world.data)
        return world

    return make
