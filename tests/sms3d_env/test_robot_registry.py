"""The robot registry (``sms3d_env.robots``): a registered class is built by name and its
configurations are taken as they are; duplicate names, classes and objects that miss a member of
``RobotSpec`` are refused naming what is wrong; an unknown name's error lists the registered ones;
the command-line choices read the registry."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import gymnasium as gym
import pytest

import sms3d_env
from sms3d_env import robot_registry
from sms3d_env.cli import build_parser
from sms3d_env.gantry import GANTRY_JOINTS, GantryConfig
from sms3d_env.robot import arm_only_model
from sms3d_env.robots import ROBOTS, RobotSpec, make_robot, register_robot, registered_robots
from sms3d_env.study.plan import SweepConfig

SMALL = {"placement": {"num_mushrooms": 8}}


@pytest.fixture
def registry(monkeypatch):
    """A copy of the registry for the test: what it registers is gone afterwards."""
    monkeypatch.setattr(robot_registry, "_ROBOTS", dict(robot_registry._ROBOTS))


def _short_rail_gantry() -> type:
    @register_robot("short_rail_gantry")
    @dataclass(frozen=True)
    class ShortRailGantry(GantryConfig):
        name: ClassVar[str] = "short_rail_gantry"
        rail_travel: float = 0.25

        def build_spec(self):
            spec = super().build_spec()
            for rail in ("rail_x", "rail_y"):
                spec.joint(rail).range = [-self.rail_travel, self.rail_travel]
            return spec

    return ShortRailGantry


def test_the_built_in_robots_are_registered_by_their_own_modules():
    assert registered_robots() == ("gantry", "jaco", "ur5e") == ROBOTS == sms3d_env.ROBOTS
    assert type(make_robot("gantry")) is GantryConfig and make_robot("jaco") == sms3d_env.RobotConfig()


def test_a_registered_robot_is_built_by_name_and_by_configuration(registry):
    cls = _short_rail_gantry()
    assert "short_rail_gantry" in registered_robots() and "short_rail_gantry" in ROBOTS  # ROBOTS is live
    assert make_robot("short_rail_gantry") == cls()
    narrow = cls(rail_travel=0.2)
    assert make_robot(narrow) is narrow
    env = gym.make("SMS3DPick-v2", robot="short_rail_gantry", scene=SMALL).unwrapped
    env.reset(seed=0)
    assert env.model.joint("gantry/rail_x").range.tolist() == pytest.approx([-0.25, 0.25])
    assert env.observation_space["joint_pos"].shape == (len(cls.joints),)
    env.close()
    assert SweepConfig(robots=("short_rail_gantry",)).robots == ("short_rail_gantry",)
    args = build_parser("sweep").parse_args(["sweep", "--out", "x", "--robot", "gantry", "short_rail_gantry"])
    assert args.robot == ["gantry", "short_rail_gantry"]


def test_any_object_that_meets_the_protocol_is_a_robot(registry):
    class Duck:  # no dataclass, no base class: only RobotSpec's members
        name, prefix, joints, approach = "duck", "gantry/", GANTRY_JOINTS, "cartesian"
        mount_pos, mount_yaw_deg, mount_roll_deg = (0.0, 0.0, 0.0), 0.0, 0.0
        tool, cup_radius, tube_length = "suction", 0.01, 0.09
        finger_kp, finger_force, finger_damping, finger_armature = 2.0, 0.25, 0.1, 0.001
        home_q = (0.0,) * 6

        def build_spec(self):
            return GantryConfig().build_spec()

    duck = Duck()
    assert isinstance(duck, RobotSpec) and make_robot(duck) is duck
    assert arm_only_model(duck).njnt == 6
    register_robot("duck", Duck)
    assert isinstance(make_robot("duck"), Duck)


def test_a_duplicate_name_is_refused(registry):
    _short_rail_gantry()
    with pytest.raises(ValueError, match="'short_rail_gantry' is already registered"):
        _short_rail_gantry()
    with pytest.raises(ValueError, match="'gantry' is already registered"):
        register_robot("gantry", GantryConfig)


def test_a_class_or_object_missing_a_member_is_refused_naming_it(registry):
    class NoJoints:
        name, prefix = "no_joints", "x/"

        def build_spec(self):
            raise AssertionError

    with pytest.raises(TypeError, match="NoJoints is not a robot class: it lacks joints of"):
        register_robot("no_joints", NoJoints)
    assert "no_joints" not in registered_robots()

    class NoApproach:
        name, prefix, joints = "no_approach", "x/", GANTRY_JOINTS

        def build_spec(self):
            raise AssertionError

    register_robot("no_approach", NoApproach)  # the class carries what a class must
    with pytest.raises(TypeError, match="lacks mount_pos, .*home_q, approach"):
        make_robot("no_approach")
    with pytest.raises(TypeError, match="the class GantryConfig"):
        make_robot(GantryConfig)


def test_a_name_or_home_that_does_not_fit_is_refused(registry):
    @dataclass(frozen=True)
    class Misnamed(GantryConfig):
        pass  # inherits name "gantry"

    with pytest.raises(ValueError, match="Misnamed.name is 'gantry'.*name: ClassVar\\[str\\] = 'other'"):
        register_robot("other", Misnamed)
    with pytest.raises(ValueError, match="GantryConfig.home_q must have 6 entries, got 5"):
        GantryConfig(home_q=(0.0,) * 5)
    with pytest.raises(ValueError, match="non-empty string"):
        register_robot("", Misnamed)


def test_an_unknown_name_lists_the_registered_ones(registry):
    _short_rail_gantry()
    with pytest.raises(ValueError, match=r"registered robots \('gantry', 'jaco', 'short_rail_gantry', 'ur5e'\), got 'ur5'"):
        make_robot("ur5")
    with pytest.raises(ValueError, match="registered robots"):
        gym.make("SMS3DPick-v2", robot="ur5")
