"""The suction seal rule (``Suction.seals``) on its own: the cup axis against the cap normal at the
contact (``PickPhysicsParams.seal_angle_deg``) and the contact's distance from the stem axis
(``seal_region`` of the cap radius), on a v1 world with the cup at home, pointing down."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import generator
import sms3d_env  # noqa: F401  (registers the ids)


@pytest.fixture(scope="module")
def cup():
    env = gym.make("SMS3DPick-v1", scene=generator.SceneConfig().replace(placement__num_mushrooms=6))
    env.reset(seed=0)
    picking = env.unwrapped.picking
    yield picking.tool, picking.world, picking.params, picking.state.target
    env.close()


def _tool_axis(world) -> np.ndarray:
    return world.data.site_xmat[world.tool_site].reshape(3, 3)[:, 2].copy()


def _tilted(axis: np.ndarray, degrees: float) -> np.ndarray:
    """``axis`` turned by ``degrees`` about a direction perpendicular to it."""
    side = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    a = np.deg2rad(degrees)
    return np.cos(a) * axis + np.sin(a) * side


def _on_cap(world, k: int, radial: float) -> np.ndarray:
    """A point on mushroom ``k``'s stem axis 2 cm above its body origin, moved ``radial`` metres
    across the axis."""
    d = world.data
    b = world.body_ids[k]
    axis = d.xmat[b].reshape(3, 3)[:, 2]
    across = _tilted(axis, 90.0)
    return d.xpos[b] + 0.02 * axis + radial * across


@settings(max_examples=60, deadline=None)
@given(angle=st.floats(0.0, 89.0))
def test_a_seal_forms_only_within_the_seal_angle(cup, angle):
    suction, world, params, target = cup
    if abs(angle - params.seal_angle_deg) < 1e-6:
        return  # the boundary itself is a matter of rounding
    normal = _tilted(_tool_axis(world), angle)
    sealed = suction.seals(target, _on_cap(world, target, 0.0), normal)
    assert sealed == (angle < params.seal_angle_deg)


@pytest.mark.parametrize("share, seals", [(0.0, True), (0.9, True), (1.1, False), (2.0, False)])
def test_a_seal_forms_only_on_the_cap_top(cup, share, seals):
    """Within ``seal_region`` x the cap radius of the stem axis, with the cup square to the cap."""
    suction, world, params, target = cup
    radial = share * params.seal_region * world.cap_radius[target]
    assert suction.seals(target, _on_cap(world, target, radial), _tool_axis(world)) == seals
