"""The trigger learned from counterfactual rollouts: paired labels, the regression's firing rule,
resumable label files, the saved run as a picker, and the settings' validation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sms3d_env.training.residual import DESCEND_TRIGGER, DESCEND_TRIGGER_RADIUS_M
from sms3d_env.training.trigger_rollouts import (
    TriggerConfig,
    collect_labels,
    fit_trigger,
    label_episode,
    train_trigger,
    trigger_env,
)

# The Jaco on 8-mushroom beds at 45 deg (at 0-30 deg its scripted picker loses almost no picks,
# and on the gantry no seed of 0-149 had a label other than 0): seed 0's scripted episode fails
# and firing at any of the first three steps within the trigger's reach rescues it; at 30 deg,
# seed 24's succeeds and firing at the first three loses it (found by a search).
SMALL = dict(num_mushrooms=8, pose_error_range_deg=(45.0, 45.0), candidates=4, robot="jaco")
RESCUED, LOST = (45.0, 0, [1, 1, 1, 0]), (30.0, 24, [-1, -1, -1, 0])


def _replay(env, seed, fire_at):
    """The trigger-only episode from ``seed`` with the trigger fired at step ``fire_at`` alone,
    run here step by step rather than by the module."""
    env.reset(seed=seed)
    done, step, info = False, 0, {}
    while not done:
        _, _, terminated, truncated, info = env.step(np.array([1.0 if step == fire_at else -1.0], np.float32))
        done = terminated or truncated
        step += 1
    return bool(info["is_success"])


def test_each_label_is_the_paired_gain_of_firing_at_that_step():
    for error, seed, expected in (RESCUED, LOST):
        env = trigger_env(TriggerConfig(**{**SMALL, "pose_error_range_deg": (error, error)}))
        try:
            observations, labels, base = label_episode(env, seed, candidates=4)
            assert labels == expected
            assert base == _replay(env, seed, fire_at=None)
            # Every labelled state is one where the trigger can act: within its reach.
            assert all(o["approach_motion"][0] < DESCEND_TRIGGER_RADIUS_M for o in observations)
        finally:
            env.close()
    # The first candidate is the first step within reach: firing there rescues the failing seed.
    _, seed, _ = RESCUED
    env = trigger_env(TriggerConfig(**SMALL))
    try:
        obs, _ = env.reset(seed=seed)
        step = 0
        while obs["approach_motion"][0] >= DESCEND_TRIGGER_RADIUS_M:
            obs, *_ = env.step(np.array([-1.0], np.float32))
            step += 1
        assert _replay(env, seed, fire_at=step) and not _replay(env, seed, fire_at=None)
        again = label_episode(env, seed, candidates=4)
        np.testing.assert_array_equal(again[0][0]["tool_pose"], label_episode(env, seed, 4)[0][0]["tool_pose"])
    finally:
        env.close()


def test_the_trigger_fires_where_the_expected_gain_passes_the_margin():
    """Regressed onto labels that depend on one observed feature (the stand-off gap: 1 nearer
    than the median, 0 farther), the policy fires only where the gain passes the margin: at a
    margin of 0.25 only in the near states, at -0.25 (fire unless it loses) in all of them."""
    env = trigger_env(TriggerConfig(**SMALL))
    try:
        observations = [o for seed in (14, 0, 6, 26) for o in label_episode(env, seed, candidates=4)[0]]
    finally:
        env.close()
    data = {k: np.stack([o[k] for o in observations]).astype(np.float32) for k in observations[0]}
    near = data["approach_motion"][:, 0] < np.median(data["approach_motion"][:, 0])
    data["labels"] = near.astype(np.int8)
    for margin, fires in ((0.25, near), (-0.25, np.ones_like(near))):
        cfg = TriggerConfig(**SMALL, epochs=150, margin=margin, learning_rate=3e-3)
        model, losses = fit_trigger(cfg, data, progress=False)
        assert losses[-1] < 0.1 * losses[0]
        mean = model.predict({k: data[k] for k in model.observation_space.spaces}, deterministic=True)[0][:, 0]
        np.testing.assert_array_equal(mean > DESCEND_TRIGGER, fires)


def test_labels_resume_from_their_files_and_are_remade_for_other_settings(tmp_path):
    cfg = TriggerConfig(out=str(tmp_path), episodes=2, seed=0, **SMALL)
    first = collect_labels(cfg, progress=False)
    path = tmp_path / "labels" / "episodes_0-1.npz"
    stamp = path.stat().st_mtime_ns
    again = collect_labels(cfg, progress=False)
    assert path.stat().st_mtime_ns == stamp  # reused, not collected again
    for k in first:
        np.testing.assert_array_equal(first[k], again[k])
    # Seed 0 fails and firing at any of its first three candidates rescues it; seed 1 succeeds.
    assert list(first["scripted_success"]) == [False, True] and list(first["labels"][first["episode"] == 0]) == [1, 1, 1, 0]
    assert len(first["labels"]) == len(first["episode"]) == len(first["tool_pose"])
    fewer = collect_labels(TriggerConfig(out=str(tmp_path), episodes=2, seed=0,
                                         **{**SMALL, "candidates": 2}), progress=False)
    assert path.stat().st_mtime_ns != stamp and np.bincount(fewer["episode"]).max() <= 2
    path.write_bytes(path.read_bytes()[:100])  # an interrupted write: made again
    np.testing.assert_array_equal(collect_labels(cfg, progress=False)["labels"], first["labels"])


def test_a_trained_trigger_runs_as_the_studys_residual_picker(tmp_path):
    from generator import SceneConfig
    from sms3d_env.pickers import run_episode
    from sms3d_env.pickers.registry import make_picker_env, parse_picker
    from sms3d_env.pose_sources.noisy import NoisyPose

    summary = train_trigger(TriggerConfig(out=str(tmp_path), episodes=2, seed=0, epochs=2, **SMALL),
                            progress=False)
    assert summary["labelled_states"] == 8 and summary["labels"] == {"-1": 0, "0": 5, "1": 3}
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["residual_trigger_only"] and saved["recipe"] == "trigger-rollouts"
    env, picker = make_picker_env(parse_picker(f"residual:{tmp_path / 'model.zip'}"),
                                  scene=SceneConfig().replace(placement__num_mushrooms=8),
                                  pose_source=NoisyPose(30.0))
    try:
        assert env.action_space.shape == (1,)
        row = run_episode(env, picker, seed=3)
        assert row["steps"] > 0 and isinstance(row["success"], bool)
    finally:
        env.close()


@settings(max_examples=40, deadline=None)
@given(margin=st.floats(allow_nan=True, allow_infinity=True), low=st.floats(-10, 100), high=st.floats(-10, 100),
       episodes=st.integers(-2, 3), workers=st.integers(-1, 3))
def test_settings_are_refused_by_name(margin, low, high, episodes, workers):
    kw = dict(margin=margin, pose_error_range_deg=(low, high), episodes=episodes, workers=workers)
    problems = {"margin": not (np.isfinite(margin) and -1 < margin < 1),
                "pose_error_range_deg": not (0 <= low <= high <= 90), "episodes": episodes < 1,
                "workers": workers < 1}
    if not any(problems.values()):
        TriggerConfig(**kw)
        return
    with pytest.raises(ValueError, match=r"TriggerConfig\.(\w+)") as err:
        TriggerConfig(**kw)
    assert problems[err.value.args[0].split(".")[1].split(" ")[0]]


def test_the_cli_refuses_bad_settings_and_lists_the_command(capsys):
    from sms3d_env.cli import main

    assert main(["train-trigger", "--margin", "2", "--out", "unused"]) == 2
    assert "TriggerConfig.margin" in capsys.readouterr().out
    assert main(["train-trigger", "descend_trigger", "--set", "learning_rate=0"]) == 2
    assert "--set: TriggerConfig.learning_rate must be a number > 0" in capsys.readouterr().out
    assert main(["train-trigger", "ppo"]) == 2
    assert "an rl recipe; sms3d train-policy trains it" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "train-trigger" in capsys.readouterr().out
