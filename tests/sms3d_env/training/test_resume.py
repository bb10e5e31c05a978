"""Run folders of the training commands: a rerun with the same settings resumes (after a kill, from
the latest checkpoint) or, finished, does nothing; other settings are refused before anything is
written, unless --overwrite."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from generator.run_folder import LOCK_FILE, RunFolderError, lock_run_folder
from sms3d_env.policies.loader import checkpoint_steps, load_model
from sms3d_env.training import TrainConfig, main, train_policy

TINY = dict(algo="ppo", total_steps=64, n_steps=64, batch_size=64, num_mushrooms=8, max_episode_steps=40,
            eval_freq=0, checkpoint_freq=0, verbose=0, net_arch=(32, 32))


def _rows(path) -> list[dict[str, str]]:
    return list(csv.DictReader(path.read_text().splitlines()))


def _steps_column(path) -> list[float]:
    return [float(r["time/total_timesteps"]) for r in _rows(path) if r.get("time/total_timesteps")]


def test_a_killed_training_resumes_from_its_latest_checkpoint_and_says_so(tmp_path):
    out = tmp_path / "run"
    recipe = tmp_path / "ppo_defaults.yml"
    recipe.write_text("recipe: rl  # TrainConfig's defaults: PPO on SMS3DPick-v1\n")
    command = [sys.executable, "-m", "sms3d_env.training", "train-policy", str(recipe), "--steps", "1024",
               "--num-mushrooms", "8",
               "--checkpoint-freq", "128", "--eval-freq", "256", "--eval-episodes", "1", "--vec-env", "dummy",
               "--out", str(out)]
    log = (tmp_path / "first.log").open("w")
    first = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 300
        while not (out / "checkpoints" / "ppo_256_steps.zip").is_file():
            assert first.poll() is None, (tmp_path / "first.log").read_text()[-3000:]
            assert time.monotonic() < deadline, "no checkpoint at 256 steps within 300 s"
            time.sleep(0.05)
    finally:
        first.kill()  # SIGKILL: no handler runs
        first.wait()
    resumed_at = max(checkpoint_steps(p) for p in (out / "checkpoints").glob("ppo_*_steps.zip"))
    kept = [r for r in _rows(out / "progress.csv") if float(r["time/total_timesteps"]) <= resumed_at]
    assert kept, "the killed run logged its evaluation at 256 steps"
    monitor_before = (out / "monitor" / "0.monitor.csv").read_text()

    second = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stdout[-3000:] + second.stderr[-3000:]
    assert f"resuming {out} from step {resumed_at} of 1024" in second.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["resumed_from_step"] == resumed_at and summary["steps"] >= 1024
    assert type(load_model(out / "model.zip")).__name__ == "PPO"
    # The earlier rows (under a header the resumed run's new columns extend), then the resumed run's.
    assert [{k: r[k] for k in kept[0]} for r in _rows(out / "progress.csv")[:len(kept)]] == kept
    steps = _steps_column(out / "progress.csv")
    assert steps == sorted(steps) and steps[-1] >= 1024
    assert (out / "monitor" / "0.monitor.csv").read_text().startswith(monitor_before)

    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "is complete" in again.stdout
    assert json.loads((out / "summary.json").read_text()) == summary


def test_a_rerun_with_other_settings_is_refused_and_leaves_the_run_usable(tmp_path, capsys):
    out = tmp_path / "run"
    cfg = TrainConfig(out=str(out), **TINY)
    train_policy(cfg)
    files = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}

    # A run's config.json is a recipe of that run.
    assert main(["train-policy", str(out / "config.json"), "--num-mushrooms", "101"]) == 2
    assert "TrainConfig.num_mushrooms" in capsys.readouterr().out
    with pytest.raises(RunFolderError, match=r"num_mushrooms \(8 → 9\).*--overwrite"):
        train_policy(TrainConfig(**{**cfg.__dict__, "num_mushrooms": 9}))
    assert main(["train-policy", str(out / "config.json"), "--seed", "3"]) == 2
    assert "holds a run made with other settings" in capsys.readouterr().out
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files
    assert main(["eval-policy", "--model", str(out / "model.zip"), "--episodes", "1"]) == 0

    # The same settings: a finished run does nothing.
    capsys.readouterr()
    assert train_policy(cfg) == json.loads((out / "summary.json").read_text())
    assert "is complete" in capsys.readouterr().out
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files
    # --overwrite starts anew.
    train_policy(TrainConfig(**{**cfg.__dict__, "seed": 1}), overwrite=True)
    assert json.loads((out / "config.json").read_text())["seed"] == 1


def test_nothing_is_written_for_a_bed_size_the_generator_refuses(tmp_path, capsys):
    recipe = tmp_path / "ppo_defaults.yml"
    recipe.write_text("recipe: rl\n")
    assert main(["train-policy", str(recipe), "--out", str(tmp_path / "new"), "--num-mushrooms", "101"]) == 2
    assert "TrainConfig.num_mushrooms" in capsys.readouterr().out
    assert not (tmp_path / "new").exists()


def test_a_resumed_run_without_a_checkpoint_starts_at_step_zero_and_says_so(tmp_path, capsys):
    out = tmp_path / "run"
    cfg = TrainConfig(out=str(out), **TINY)
    train_policy(cfg)
    (out / "summary.json").unlink()  # as if killed before it finished
    capsys.readouterr()
    train_policy(cfg)
    assert f"resuming {out} from step 0 of 64 (no complete checkpoint yet)" in capsys.readouterr().out
    assert _steps_column(out / "progress.csv") == [64.0]


def test_a_sac_run_resumes_with_its_replay_buffer_and_observation_statistics(tmp_path, capsys):
    from sms3d_env.policies.files import ObservationStats

    out = tmp_path / "run"
    cfg = TrainConfig(out=str(out), **{**TINY, "algo": "sac", "total_steps": 200, "learning_starts": 50,
                                       "batch_size": 32, "checkpoint_freq": 100, "normalize": True})
    train_policy(cfg)
    at_100 = ObservationStats.load(out / "checkpoints" / "sac_obs_rms_100_steps.npz")
    for name in ("summary.json", "model.zip", "obs_rms.npz", "checkpoints/sac_200_steps.zip"):
        (out / name).unlink()  # as if killed after the checkpoint at 100 steps
    capsys.readouterr()
    assert train_policy(cfg)["steps"] == 200
    assert f"resuming {out} from step 100 of 200" in capsys.readouterr().out
    # SB3 stores a step's transition after the callbacks ran: 99 at the checkpoint of 100, and
    # 99 more since; a buffer not restored would hold 99.
    with np.load(out / "checkpoints" / "sac_replay_buffer_200_steps.npz", allow_pickle=False) as buffer:
        assert int(buffer["pos"]) == 198 and not buffer["full"]
    # The statistics went on from the checkpoint's: the resumed run's reset and 100 steps more.
    count = ObservationStats.load(out / "obs_rms.npz").obs["tool_pose"].count
    assert count == pytest.approx(at_100.obs["tool_pose"].count + 101)


@pytest.mark.parametrize("best_at", [100, 200])
def test_a_resume_drops_a_best_model_of_the_training_it_redoes(tmp_path, best_at):
    import gymnasium as gym

    from sms3d_env.training.rl import _evaluation

    (tmp_path / "eval").mkdir()
    means = {100: [5.0, 1.0], 200: [1.0, 5.0]}[best_at]
    np.savez(tmp_path / "eval" / "evaluations.npz", timesteps=np.array([100, 200]),
             results=np.array([[means[0]], [means[1]]]), ep_lengths=np.array([[10], [10]]))
    (tmp_path / "best").mkdir()
    (tmp_path / "best" / "best_model.zip").write_bytes(b"model")
    cfg = TrainConfig(out=str(tmp_path), eval_freq=100)
    callback = _evaluation(gym.make("CartPole-v1"), None, tmp_path, cfg, resumed_at=150)
    assert callback.evaluations_timesteps == [100]
    if best_at == 100:  # the best model predates the checkpoint: kept, and the bar to beat stays
        assert (tmp_path / "best" / "best_model.zip").is_file() and callback.best_mean_reward == 5.0
    else:  # saved after it, by training this run redoes: gone, the next evaluation saves anew
        assert not (tmp_path / "best").exists() and callback.best_mean_reward == -np.inf


@pytest.mark.parametrize("recipe", ["ppo", "pick_policy"])
def test_a_training_in_a_folder_another_run_holds_is_refused_naming_it(tmp_path, capsys, recipe):
    out = tmp_path / "run"
    lock = lock_run_folder(out)  # as a first train-policy running there holds it
    try:
        assert main(["train-policy", recipe, "--out", str(out), "--steps" if recipe == "ppo" else "--seed", "64"]) == 2
        assert f"{out}: another run is in progress in this folder (process {os.getpid()}" in capsys.readouterr().out
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
    finally:
        lock.close()


def test_a_finished_run_in_a_read_only_folder_is_reported_with_nothing_to_do(tmp_path, read_only_child):
    out = tmp_path / "run"
    train_policy(TrainConfig(out=str(out), **TINY))
    (out / LOCK_FILE).unlink()  # a finished run copied from elsewhere, without its lock file
    for p in (out, *out.rglob("*")):
        p.chmod(0o555 if p.is_dir() else 0o444)
    done = subprocess.run([sys.executable, "-m", "sms3d_env.training", "train-policy", str(out / "config.json")],
                          capture_output=True, text=True, check=False, **read_only_child)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"{out} is complete (summary.json); nothing to do" in done.stdout
