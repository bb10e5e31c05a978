"""Learned pickers end to end: the BC/DAgger recipe trains, saves and loads; eval-policy reports
``success K/N``; pickers by name; the sweep runs a learned picker on the scripted picker's
episodes; the shipped policy loads without a download."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.pickers.registry import PickerSpec, make_picker_env, parse_picker
from sms3d_env.policies.loader import SHIPPED_POLICY
from sms3d_env.study.plan import SweepConfig
from sms3d_env.study.sweep import run_sweep
from sms3d_env.training import main
from sms3d_env.training.imitation import BCConfig, train_bc


@pytest.fixture(scope="module")
def bc_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bc")
    cfg = BCConfig(episodes=2, num_mushrooms=(8,), epochs=2, dagger_rounds=1, dagger_episodes=1,
                   dagger_epochs=1, net_arch=(32, 32), out=str(out))
    return out, cfg, train_bc(cfg, progress=False)


def test_bc_recipe_writes_a_policy_that_loads_and_acts(bc_run):
    out, cfg, summary = bc_run
    assert summary["demo_episodes_kept"] >= 1 and summary["training_steps"] > summary["demo_steps"]
    saved = json.loads((out / "config.json").read_text())
    assert saved["env_id"] == "SMS3DPickTrain-v2" and saved["env_options"]["suction_mode"] == "latched"
    actor = PolicyActor(out / "model.zip")
    env, picker = make_picker_env(parse_picker(f"policy:{out / 'model.zip'}"))
    obs, _ = env.reset(seed=0)
    action = picker(obs)
    assert action.shape == (7,) and np.all(np.abs(action) <= 1.0)
    assert actor.env_options == saved["env_options"]
    # The normaliser lives inside the model: its statistics are the demonstrations'.
    features = actor.model.policy.features_extractor
    assert features.mean.shape[0] == sum(np.prod(s.shape) for s in env.observation_space.spaces.values())


def test_a_rerun_reuses_the_demonstrations_and_the_dagger_data(bc_run, capsys, tmp_path):
    import shutil

    out, cfg, summary = bc_run
    killed = tmp_path / "killed"  # the run as if killed after its datasets were recorded
    shutil.copytree(out, killed)
    (killed / "summary.json").unlink()
    datasets = sorted(killed.glob("datasets/bc/*/data/main_data.hdf5"))
    assert [p.parents[1].name for p in datasets] == ["dagger1-0-v0", "demos-0-v0"]
    before = {p: p.stat().st_mtime_ns for p in datasets}
    resumed = train_bc(BCConfig(**{**cfg.__dict__, "out": str(killed)}), progress=False)
    assert "reusing bc/dagger1-0-v0, bc/demos-0-v0" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in datasets} == before
    assert (resumed["demo_steps"], resumed["training_steps"]) == (summary["demo_steps"], summary["training_steps"])


def test_a_rerun_with_other_settings_is_refused_and_keeps_the_model(bc_run, capsys):
    from generator.run_folder import RunFolderError

    out, cfg, summary = bc_run
    model = (out / "model.zip").read_bytes()
    with pytest.raises(RunFolderError, match=r"epochs \(2 → 3\).*--overwrite"):
        train_bc(BCConfig(**{**cfg.__dict__, "epochs": 3}), progress=False)
    assert main(["train-policy", str(out / "config.json"), "--hyperparams", "epochs=3"]) == 2
    assert "holds a run made with other settings" in capsys.readouterr().out
    assert (out / "model.zip").read_bytes() == model
    assert train_bc(cfg, progress=False) == summary and "is complete" in capsys.readouterr().out


def test_eval_policy_prints_the_success_line(bc_run, capsys):
    out, _, _ = bc_run
    assert main(["eval-policy", "--model", str(out / "model.zip"), "--episodes", "2",
                 "--num-mushrooms", "8", "--json", str(out / "eval.json")]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("success ") and "/2 (" in last and "95 % CI" in last
    res = json.loads((out / "eval.json").read_text())
    assert len(res["per_episode"]) == 2 and res["env_id"] == "SMS3DPickTrain-v2"


def test_eval_policy_names_a_missing_model(capsys, tmp_path):
    assert main(["eval-policy", "--model", str(tmp_path / "nope.zip")]) == 2
    assert "nope.zip" in capsys.readouterr().out


@pytest.mark.parametrize("text, error", [("nonsense", ValueError), ("scripted:x.zip", ValueError),
                                         ("policy:/no/such/model.zip", FileNotFoundError)])
def test_parse_picker_refuses_bad_names(text, error):
    with pytest.raises(error):
        parse_picker(text)


def test_parse_picker_defaults():
    assert parse_picker("scripted") == PickerSpec("scripted", None)
    assert parse_picker("policy") == PickerSpec("policy", None)  # the shipped one
    assert parse_picker("policy").model_path.is_file()
    assert parse_picker("scripted").model_path is None


@pytest.mark.parametrize("text", ["residual", "residual:/no/such/model.zip", "residual:runs/trigger/model.zip"])
def test_parse_picker_says_the_residual_pickers_were_removed_and_where_the_finding_is(text):
    """The residual pickers (residual PPO, the learned descend trigger) were removed: asking for
    one names it, why and where the measurement lives, before looking for any file."""
    with pytest.raises(ValueError, match=r"picker 'residual.*removed in 0.2.0: residual PPO never beat the "
                                         r"scripted picker .*docs/results-training.md") as err:
        parse_picker(text)
    assert "CHANGELOG.md" in str(err.value) and "policy[:PATH]" in str(err.value)


def test_sweep_runs_a_learned_picker_on_the_same_episodes(bc_run, tmp_path):
    out, _, _ = bc_run
    common = dict(errors_deg=(0.0,), episodes=2, chunk=2, num_mushrooms=8)
    scripted = run_sweep(SweepConfig(**common), tmp_path / "scripted", progress=False)
    learned = run_sweep(SweepConfig(picker=f"policy:{out / 'model.zip'}", **common),
                        tmp_path / "learned", progress=False)
    assert {r["picker"] for r in scripted} == {"scripted"}
    assert {r["picker"] for r in learned} == {f"policy:{out.name}"}
    # Paired: the same scene and target in every episode, whatever the picker.
    assert [(r["seed"], r["target"], r["tilt_deg"]) for r in scripted] == \
        [(r["seed"], r["target"], r["tilt_deg"]) for r in learned]
    with pytest.raises(ValueError, match="picker"):
        run_sweep(SweepConfig(**common), tmp_path / "learned", progress=False)


def test_the_shipped_policy_loads_and_was_trained_on_the_training_id():
    assert SHIPPED_POLICY.is_file(), "sms3d_env/weights/pick_policy/model.zip is not in the package"
    actor = PolicyActor(SHIPPED_POLICY)
    assert actor.env_id == "SMS3DPickTrain-v2"
    metrics = json.loads((SHIPPED_POLICY.parent / "metrics.json").read_text())
    # What the package promises of it: at least 95 % of what the scripted picker picks on the same episodes.
    for condition in ("oracle", "noisy_10deg"):
        assert metrics[condition]["successes"] >= 0.95 * metrics[condition]["scripted_successes"], condition


def test_learning_curve_reads_evaluations_with_their_wall_time(tmp_path, capsys):
    from sms3d_env.training.learning_curve import read_curve

    run = tmp_path / "ppo_s0"
    run.mkdir()
    (run / "progress.csv").write_text(
        "time/total_timesteps,time/time_elapsed,eval/success_rate\n"
        "2048,10,\n4096,,0.25\n6144,31,\n8192,,0.5\n")
    curve = read_curve(run)
    assert [{k: p[k] for k in ("steps", "wall_s", "success")} for p in curve] == [
        {"steps": 4096.0, "wall_s": 10.0, "success": 0.25}, {"steps": 8192.0, "wall_s": 31.0, "success": 0.5}]
    assert all(math.isnan(p["pregrasp_start"]) for p in curve)  # no annealed curriculum
    annealed = tmp_path / "ppo_anneal_s0"
    annealed.mkdir()
    (annealed / "progress.csv").write_text(
        "time/total_timesteps,time/time_elapsed,curriculum/pregrasp_start,eval/success_rate\n"
        "2048,10,0.75,\n4096,,,0.25\n6144,31,0.5,\n8192,,,0.5\n")
    assert [p["pregrasp_start"] for p in read_curve(annealed)] == [0.75, 0.5]
    assert main(["learning-curve", str(run), str(annealed), "--out", str(tmp_path / "c.png")]) == 0
    assert "| ppo_s0 | 2 | 8192 |" in capsys.readouterr().out
    assert (tmp_path / "c.png").stat().st_size > 5_000
    # A second phase started from the annealed run's 6144-step checkpoint continues its curve.
    second = tmp_path / "phase2"
    second.mkdir()
    (second / "config.json").write_text(json.dumps(
        {"init_model": str(annealed / "checkpoints" / "ppo_6144_steps.zip")}))
    (second / "progress.csv").write_text(
        "time/total_timesteps,time/time_elapsed,eval/success_rate\n2048,5,\n4096,,0.75\n")
    assert [(p["steps"], p["wall_s"], p["success"]) for p in read_curve(second)] == [
        (4096.0, 10.0, 0.25), (6144.0 + 4096.0, 31.0 + 5.0, 0.75)]
    (run / "progress.csv").write_text("time/total_timesteps,time/time_elapsed\n2048,10\n")
    with pytest.raises(ValueError, match="progress.csv"):
        read_curve(run)
