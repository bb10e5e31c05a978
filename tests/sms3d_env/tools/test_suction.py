"""The suction tool's rules (``sms3d_env.tools.suction``): the seal rule ``Suction.seals`` (the cup
axis against the cap normal at the contact, ``PickPhysicsParams.seal_angle_deg``, and the
contact's distance from the stem axis, ``seal_region`` of the cap radius, on a v1 world with the
cup at home, pointing down), the valve and its grip weld, the seal's load (``grip_wrench``) and
the dead ends."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import generator
import sms3d_env  # noqa: F401  (registers the ids)
from sms3d_env.episode_state import EpisodeState
from sms3d_env.gantry import GantryConfig
from sms3d_env.physics_params import V1_PHYSICS, PickPhysicsParams
from sms3d_env.tools import Suction


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


@pytest.mark.parametrize("latched", [False, True])
def test_an_off_command_releases_the_seal_unless_the_valve_is_latched(make_world, upright, latched):
    world = make_world(GantryConfig())
    state = EpisodeState(target=upright)
    suction = Suction(world, PickPhysicsParams(), state, latched)
    open_cup = world.cup_mask
    assert suction.command(1.0)
    suction.grip(upright)
    assert state.grip == upright and state.ever_gripped_target
    assert world.data.eq_active[world.grip_eq[upright]]
    # While sealed, the weld is the cup-cap interface: the cup face touches no mushroom.
    assert world.model.geom_conaffinity[world.cup_geom] == 0
    assert suction.command(-1.0) is latched
    assert (state.grip == upright) is latched
    assert bool(world.data.eq_active[world.grip_eq[upright]]) is latched
    if not latched:
        m = world.model
        assert (m.geom_contype[world.cup_geom], m.geom_conaffinity[world.cup_geom]) == open_cup


@pytest.mark.parametrize("latched, grip_on, detached, dead", [
    (False, "target", True, False),     # detached and held: the pick goes on
    (False, "none", True, True),        # knocked off its roots, not held
    (False, "neighbour", False, False),  # a seal on a neighbour can still be let go
    (True, "neighbour", False, True),   # ... unless the valve is latched
    (True, "target", False, False),
    (False, "none", False, False),
])
def test_a_dead_end_is_a_target_knocked_off_or_a_latched_seal_on_a_neighbour(make_world, upright, latched, grip_on,
                                                                             detached, dead):
    world = make_world(GantryConfig())
    neighbour = (upright + 1) % len(world.body_ids)
    grip = {"target": upright, "neighbour": neighbour, "none": -1}[grip_on]
    state = EpisodeState(target=upright, grip=grip, target_detached=detached)
    assert Suction(world, PickPhysicsParams(), state, latched).dead_end() is dead


def _held_by_the_cup(env_id: str):
    """An env whose target is off its roots and sealed to the cup where the cup is now."""
    env = gym.make(env_id, scene={"placement": {"num_mushrooms": 4}}).unwrapped  # the id's own placement
    env.reset(seed=0)
    m, d = env.model, env.data
    k = env.picking.state.target
    b = env.world.body_ids[k]
    d.eq_active[env.world.root_eq[k]] = 0  # detached, and moved up to the cup
    qadr = m.jnt_qposadr[m.body_jntadr[b]]
    d.qpos[qadr : qadr + 3] += d.site_xpos[env.world.tool_site] - d.site_xpos[env.world.cap_top_sites[k]]
    mujoco.mj_forward(m, d)
    env.picking.tool.grip(k, d.site_xpos[env.world.tool_site].copy())
    env.picking.state.target_detached = True
    return env, k, b


def test_env_grip_wrench_is_about_the_cup_contact():
    """A detached mushroom held by the cup alone, with a known extra load: the env's seal reading
    is the weight plus the load, and its moment is taken about the cup face, not the stem base."""
    env, k, b = _held_by_the_cup("SMS3DPick-v2")
    m, d = env.model, env.data
    m.body_gravcomp[b] = 0.0
    f_app = np.array([0.1, 0.05, -0.2])
    d.xfrc_applied[b, :3] = f_app
    for _ in range(1500):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    force, moment, z = env.picking.tool.grip_wrench()
    load = f_app + m.body_subtreemass[b] * m.opt.gravity
    np.testing.assert_allclose(force, -load, atol=2e-3)
    pc = d.site_xpos[env.world.tool_site]
    np.testing.assert_allclose(moment, -np.cross(d.xipos[b] - pc, load), atol=2e-4)
    np.testing.assert_allclose(z, d.site_xmat[env.world.tool_site].reshape(3, 3)[:, 2])


def _overload_then_rest(env, b: int, force: np.ndarray, steps: int) -> bool:
    """Pull the held mushroom with ``force`` for ``steps`` physics steps, then 50 ms with none,
    the seal's rule read after every step as the env does; whether the seal still holds."""
    m, d, tool = env.model, env.data, env.picking.tool
    for i in range(steps + round(0.05 / m.opt.timestep)):
        d.xfrc_applied[b, :3] = force if i < steps else 0.0
        mujoco.mj_step(m, d)
        tool.check_hold()
    return env.picking.state.grip >= 0


def test_the_seal_outlasts_a_one_step_impulse_but_not_a_sustained_overload():
    """The grip-loss rule low-passes the seal's load over ``seal_response_time``: a pull of twice
    the holding force for one physics step (an impulse that grows as the step shrinks) leaves
    the seal on; the same pull for 50 ms lets go and counts as a lost grip."""
    env, k, b = _held_by_the_cup("SMS3DPick-v1")
    pull = np.array([0.0, 0.0, 2.0 * env.picking.params.holding_force])
    assert _overload_then_rest(env, b, pull, steps=1)
    assert 0.0 < env.picking.state.grip_util < 1.0
    assert not env.picking.state.grip_lost
    assert not _overload_then_rest(env, b, pull, steps=round(0.05 / env.model.opt.timestep))
    assert env.picking.state.grip_lost


def _place_cup(world, k: int, tilt_deg: float, across: float = 0.0) -> None:
    """Put the cup face 0.5 mm above mushroom ``k``'s cap top (moved ``across`` metres over the
    cap), its axis along the stem into the cap turned by ``tilt_deg``: written straight into the
    site's pose, which is all ``lip_gaps`` reads of the robot."""
    d = world.data
    b = world.body_ids[k]
    stem = d.xmat[b].reshape(3, 3)[:, 2]
    z = -_tilted(stem, tilt_deg)
    x = np.cross(z, [0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    frame = np.stack([x, np.cross(z, x), z], axis=1)
    top = d.site_xpos[world.cap_top_sites[k]] + across * _tilted(stem, 90.0)
    d.site_xpos[world.tool_site] = top - 0.0005 * z
    d.site_xmat[world.tool_site] = frame.ravel()


@pytest.fixture()
def lip_cup(cup):
    suction, world, params, target = cup
    d = world.data
    saved = d.site_xpos[world.tool_site].copy(), d.site_xmat[world.tool_site].copy()
    lip = Suction(world, PickPhysicsParams(lip_seal=True), EpisodeState(target=target))
    yield lip, world, target
    d.site_xpos[world.tool_site], d.site_xmat[world.tool_site] = saved


def test_a_square_cup_on_the_cap_top_meets_the_cap_with_its_whole_lip(lip_cup):
    lip, world, target = lip_cup
    _place_cup(world, target, 0.0)
    gaps = lip.lip_gaps(target)
    assert np.isfinite(gaps).all() and gaps.max() - gaps.min() < 1e-3
    assert lip.seals(target, np.zeros(3), np.zeros(3))


@pytest.mark.parametrize("tilt_deg", [20.0, 30.0])
def test_a_cup_tilted_past_its_compliance_does_not_seal(lip_cup, tilt_deg):
    """A rigid lip tilted by theta spreads by about 2a tan(theta) (7.3 mm at 20 degrees for a
    20 mm cup), more than the 5 mm a bellows absorbs: the far rim stands off the cap and leaks."""
    lip, world, target = lip_cup
    _place_cup(world, target, tilt_deg)
    gaps = lip.lip_gaps(target)
    assert not np.isfinite(gaps).all() or gaps.max() - gaps.min() > lip.params.lip_compliance
    assert not lip.seals(target, np.zeros(3), np.zeros(3))


def test_the_scripted_picker_20_degrees_off_seals_with_one_contact_but_not_with_the_whole_lip():
    """The same episodes on v1's picking model (``V1_PHYSICS``), the lip rule on or off: the
    one-contact rule seals where the tilted rim first touches the dome; the lip rule finds the
    far rim more than the lip's compliance off the cap."""
    from sms3d_env.pickers.episode import run_episode
    from sms3d_env.pickers.scripted import ScriptedPicker

    outcomes = {}
    for lip in (False, True):
        env = gym.make("SMS3DPick-v1", scene=generator.SceneConfig().replace(placement__num_mushrooms=10),
                       pose_source="noisy", pose_error_deg=20.0,
                       physics=PickPhysicsParams(**{**V1_PHYSICS, "lip_seal": lip}))
        picker = ScriptedPicker.for_env(env)
        outcomes[lip] = [run_episode(env, picker, seed)["failure_cause"] for seed in (1_000_000, 1_000_001)]
        env.close()
    assert outcomes == {False: [None, None], True: ["no_seal", "no_seal"]}


def test_a_lip_partly_past_the_caps_edge_leaks(lip_cup):
    lip, world, target = lip_cup
    _place_cup(world, target, 0.0, across=world.cap_radius[target])
    assert not np.isfinite(lip.lip_gaps(target)).all()
    assert not lip.seals(target, np.zeros(3), np.zeros(3))


def test_the_holding_force_rises_over_the_evacuation_time():
    from sms3d_env.physics import grip_utilisation

    p = PickPhysicsParams(lip_seal=True)
    full = grip_utilisation(2.0, 0.0, 0.0, 0.0, p)
    assert grip_utilisation(2.0, 0.0, 0.0, 0.0, p, vacuum_fraction=0.5) == pytest.approx(2 * full)
