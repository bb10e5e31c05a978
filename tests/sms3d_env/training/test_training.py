"""stable-baselines3 pick policies: short PPO/SAC runs, saved models, evaluation, logs, config checks."""

from __future__ import annotations

import argparse
import csv
import json
import math

import numpy as np
import pytest

from sms3d_env.policies.files import PolicyFileError
from sms3d_env.policies.loader import load_model
from sms3d_env.training import TrainConfig, evaluate_policy_success, register, train_policy
from sms3d_env.training.rl import InitModelError

FAST = dict(num_mushrooms=8, max_episode_steps=40, eval_freq=128, eval_episodes=1,
            checkpoint_freq=128, verbose=0, net_arch=(32, 32))


def _columns(path) -> list[str]:
    with open(path, newline="") as f:
        return next(csv.reader(f))


def _check_eval(model_path) -> None:
    res = evaluate_policy_success(model_path, episodes=2, pose_error_deg=10.0, seed=5)
    assert 0.0 <= res["success_rate"] <= 1.0
    lo, hi = res["ci95"]
    assert 0.0 <= lo <= res["success_rate"] <= hi <= 1.0
    assert res["episodes"] == 2
    assert res["successes"] + sum(res["failure_causes"].values()) == 2
    assert 0 <= res["target_held_at_end"] <= res["episodes"]
    assert math.isfinite(res["mean_return"])


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo")
    cfg = TrainConfig(algo="ppo", total_steps=256, n_steps=128, batch_size=64, out=str(out), **FAST)
    return out, train_policy(cfg)


def test_ppo_writes_model_that_loads_and_acts(ppo_run):
    out, summary = ppo_run
    assert summary["steps"] >= 256 and summary["steps_per_s"] > 0
    assert (out / "model.zip").exists() and (out / "best" / "best_model.zip").exists()
    assert sorted(p.name for p in (out / "checkpoints").iterdir())  # at least one checkpoint
    assert json.loads((out / "config.json").read_text())["algo"] == "ppo"
    model = load_model(out / "model.zip")
    assert type(model).__name__ == "PPO"
    obs = {k: np.asarray(v)[None] for k, v in model.observation_space.sample().items()}
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (1, 7) and np.all(np.abs(action) <= 1.0)


def test_ppo_evaluation_rate_and_interval(ppo_run):
    _check_eval(ppo_run[0] / "model.zip")


def test_ppo_csv_log_columns(ppo_run):
    out, _ = ppo_run
    cols = _columns(out / "progress.csv")
    for c in ("eval/success_rate", "eval/mean_reward", "time/total_timesteps", "rollout/ep_rew_mean",
              "train/value_loss"):
        assert c in cols, (c, cols)
    monitor = next((out / "monitor").glob("*.monitor.csv"))
    assert "is_success" in monitor.read_text().splitlines()[1]


def test_sac_short_run(tmp_path):
    cfg = TrainConfig(algo="sac", total_steps=200, learning_starts=100, batch_size=32, out=str(tmp_path),
                      **FAST)
    summary = train_policy(cfg)
    assert summary["steps"] >= 200
    assert type(load_model(tmp_path / "model.zip")).__name__ == "SAC"
    cols = _columns(tmp_path / "progress.csv")
    assert "eval/success_rate" in cols and "train/actor_loss" in cols
    _check_eval(tmp_path / "model.zip")


@pytest.mark.parametrize(("kw", "field"), [
    ({"algo": "a2c"}, "algo"),
    ({"total_steps": 0}, "total_steps"),
    ({"n_envs": 0}, "n_envs"),
    ({"pose_source": "camera"}, "pose_source"),
    ({"pose_error_deg": -1.0}, "pose_error_deg"),
    ({"pose_error_deg": 10.0}, "pose_error_deg"),  # oracle with an error
    ({"reward_type": "shaped"}, "reward_type"),
    ({"num_mushrooms": 0}, "num_mushrooms"),
    ({"max_wall_s": 0.0}, "max_wall_s"),
    ({"learning_rate": 0.0}, "learning_rate"),
    ({"net_arch": ()}, "net_arch"),
    ({"target_kl": 0.0}, "target_kl"),
    ({"target_kl": float("nan")}, "target_kl"),
    ({"algo": "sac", "target_kl": 0.01}, "target_kl"),
    ({"posture_target": "home"}, "posture_target"),
    ({"pregrasp_start": 1.5}, "pregrasp_start"),
    ({"pregrasp_start": -0.1}, "pregrasp_start"),
    ({"pose_source": "noisy", "position_noise": 0.002, "pose_error_range_deg": (0.0, 30.0)}, "pose_error_range_deg"),
    ({"gamma": 0.0}, "gamma"),
    ({"vec_env": "threads"}, "vec_env"),
    ({"flat_observation": 1}, "flat_observation"),
])
def test_invalid_config_names_field(kw, field):
    with pytest.raises(ValueError, match=f"TrainConfig.{field}"):
        TrainConfig(**kw)


def test_config_roundtrip_and_frozen():
    cfg = TrainConfig(pose_source="noisy", pose_error_deg=10.0, net_arch=[64, 64])
    assert cfg.net_arch == (64, 64)
    assert TrainConfig.from_dict(json.loads(json.dumps(cfg.__dict__))) == cfg
    with pytest.raises(AttributeError):
        cfg.algo = "sac"  # type: ignore[misc]


def test_a_kl_limited_tool_posture_run_is_rebuilt_with_its_env_options(tmp_path):
    """What a KL-limited run depends on reaches PPO and, through ``config.json``, every later
    evaluation of the policy."""
    from stable_baselines3 import PPO

    from sms3d_env.pickers.policy import PolicyActor

    cfg = TrainConfig(algo="ppo", total_steps=128, n_steps=128, batch_size=64, target_kl=0.01,
                      posture_target="tool", learning_rate=1e-4, gamma=0.999, out=str(tmp_path),
                      **{**FAST, "eval_freq": 0, "checkpoint_freq": 0})
    assert cfg.env_kwargs()["controller"] == {"posture_target": "tool"}
    train_policy(cfg)
    model = PPO.load(str(tmp_path / "model.zip"), device="cpu")
    assert model.target_kl == 0.01 and model.learning_rate == 1e-4 and model.gamma == 0.999
    assert PolicyActor(tmp_path / "model.zip").env_options == {"controller": {"posture_target": "tool"}}
    assert "controller" not in TrainConfig().env_kwargs()


def test_a_run_of_a_removed_experiment_is_refused_saying_why(tmp_path):
    """A residual run's or the descend trigger's ``config.json`` (``residual_scale`` > 0: their
    actions corrected the scripted picker's in a removed wrapper) is refused by ``PolicyActor``,
    as ``init_model`` and as a ``TrainConfig``, naming the removal; an older rl run's record of
    removed fields at their defaults still reads."""
    from sms3d_env.pickers.policy import PolicyActor

    cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v2", total_steps=128, n_steps=128, batch_size=64,
                      out=str(tmp_path / "run"), **{**FAST, "eval_freq": 0, "checkpoint_freq": 0})
    train_policy(cfg)
    config = tmp_path / "run" / "config.json"
    saved = json.loads(config.read_text())
    assert "residual_scale" not in saved and saved["recipe"] == "rl"
    older = {**saved, "residual_scale": 0.0, "residual_until_held": False, "use_sde": False}
    assert TrainConfig.from_dict(older) == cfg  # an older run's record, at the defaults
    with pytest.raises(ValueError, match="TrainConfig.use_sde=True: removed on 2026-12-06"):
        TrainConfig.from_dict({**saved, "use_sde": True})
    with pytest.raises(ValueError, match="residual_scale=0.5: residual PPO .* removed on 2026-12-07"):
        TrainConfig.from_dict({**saved, "residual_scale": 0.5})
    config.write_text(json.dumps({**saved, "recipe": "residual", "residual_scale": 0.5}))
    with pytest.raises(PolicyFileError, match="is a residual policy: residual PPO .* never beat the scripted picker"):
        PolicyActor(tmp_path / "run" / "model.zip")
    config.write_text(json.dumps({**saved, "recipe": "trigger-rollouts", "residual_scale": 1.0,
                                  "residual_descend_trigger": True, "residual_trigger_only": True}))
    with pytest.raises(PolicyFileError, match="the learned descend trigger .* removed on 2026-12-07"):
        PolicyActor(tmp_path / "run" / "model.zip")
    continued = TrainConfig(**{**cfg.__dict__, "init_model": str(tmp_path / "run" / "model.zip"),
                               "out": str(tmp_path / "next")})
    with pytest.raises(InitModelError, match="is a residual policy: the learned descend trigger"):
        train_policy(continued)


def test_pregrasp_starts_are_for_training_only(tmp_path, monkeypatch):
    """The training envs start a share of their episodes on the way to a pre-grasp pose and draw
    their beds from a pool; the periodic evaluation and every later evaluation of the saved policy
    start at home on fresh beds."""
    from sms3d_env.pickers.policy import PolicyActor
    from sms3d_env.start_states import PregraspStart
    from sms3d_env.training import rl

    built = []
    real_vec_env = rl.vec_env
    monkeypatch.setattr(rl, "vec_env", lambda kw, *a, **k: built.append(kw) or real_vec_env(kw, *a, **k))
    cfg = TrainConfig(algo="ppo", total_steps=128, n_steps=128, batch_size=64, pregrasp_start=0.5, scene_pool=2,
                      out=str(tmp_path), **{**FAST, "checkpoint_freq": 0})
    train_policy(cfg)
    training, evaluation = built
    assert training["start"] == PregraspStart(0.5) and "start" not in evaluation
    assert training["scene"] == {"config": {"placement": {"num_mushrooms": 8}}, "pool": 2}
    assert evaluation["scene"] == training["scene"]["config"]
    assert json.loads((tmp_path / "config.json").read_text())["pregrasp_start"] == 0.5
    assert PolicyActor(tmp_path / "model.zip").env_options == {}
    assert "start" not in TrainConfig().env_kwargs()


def test_annealing_reaches_the_training_envs_through_their_wrappers(tmp_path):
    """Two vectorised, normalised envs: each rollout's share is set in both (by env_method through
    VecNormalize, the monitor and gymnasium's wrappers) and logged; home starts are recorded."""
    import csv

    cfg = TrainConfig(algo="ppo", total_steps=256, n_steps=64, batch_size=64, n_envs=2, normalize=True,
                      pregrasp_start=0.5, pregrasp_anneal=True, out=str(tmp_path),
                      **{**FAST, "eval_freq": 0, "checkpoint_freq": 0})
    train_policy(cfg)
    rows = list(csv.DictReader((tmp_path / "progress.csv").open()))
    shares = [float(r["curriculum/pregrasp_start"]) for r in rows if r.get("curriculum/pregrasp_start")]
    assert shares and all(v == 0.5 for v in shares)  # no home start has succeeded yet
    starts = [row["start"] for f in sorted((tmp_path / "monitor").glob("*.monitor.csv"))
              for row in csv.DictReader(f.read_text().splitlines()[1:])]  # line 1: the monitor's header
    assert starts and set(starts) <= {"home", "pregrasp"}


def test_the_best_model_is_saved_with_its_observation_statistics(tmp_path):
    """``best/best_model.zip`` loads like the final model: its VecNormalize statistics and the
    run's config.json lie beside it (they were missing, and the statistics drift after the best)."""
    from sms3d_env.pickers.policy import PolicyActor

    for normalize in (True, False):
        out = tmp_path / str(normalize)
        cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v2", total_steps=256, n_steps=128, batch_size=64,
                          normalize=normalize, out=str(out), **{**FAST, "checkpoint_freq": 0})
        train_policy(cfg)
        actor = PolicyActor(out / "best" / "best_model.zip")
        assert (actor.obs_stats is not None) == normalize and actor.env_id == cfg.env_id
        assert (out / "best" / "config.json").read_text() == (out / "config.json").read_text()


def _train_policy_command(argv, capsys):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    a = parser.parse_args(["train-policy", *argv])
    code = a.func(a)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("argv, flag", [
    (["pick_policy", "--steps", "5"], "--steps: a bc recipe has no total_steps"),
    (["pick_policy", "--init-model", "runs/x/model.zip"], "--init-model: a bc recipe has no init_model"),
    (["ppo", "--demos", "sms3d/pick-v2/x-v0"], "--demos: an rl recipe has no demos"),
    (["ppo", "--num-mushrooms", "10", "25"], "--num-mushrooms: an rl recipe trains on one bed size"),
    (["ppo", "--hyperparams", "lr=1e-3"], "--hyperparams: no field lr in an rl recipe"),
    (["ppo", "--hyperparams", "learning_rate"], "--hyperparams 'learning_rate': must be KEY=VALUE"),
    (["ppo", "--hyperparams", "learning_rate=2"], "--hyperparams: TrainConfig.learning_rate must be in (0, 1)"),
    (["pick_policy", "--hyperparams", "epochs=0"], "--hyperparams: BCConfig.epochs must be an integer >= 1"),
    (["--recipe", "bc", "--demo-episodes", "0"], "--demo-episodes: BCConfig.episodes must be"),
    ([], "name a recipe"),
    (["no-such-recipe"], "no recipe file no-such-recipe (shipped recipes: pick_policy, ppo)"),
    (["ppo", "--use-sde"], "--use-sde: removed on 2026-12-06"),
    (["ppo", "--use-sde", "--critic-warmup-steps", "5"], "--critic-warmup-steps, --use-sde: removed on 2026-12-06"),
], ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_train_policy_refuses_what_its_recipe_cannot_use_by_name(capsys, argv, flag):
    code, out, _ = _train_policy_command(argv, capsys)
    assert code == 2 and flag in out, out


def test_deprecated_train_policy_flags_still_set_their_field_with_a_dated_warning(monkeypatch, capsys):
    """The flags that set a field before recipes were data still work for one release: the same
    config as the recipe with ``--hyperparams``, and a warning naming the date and the field."""
    from sms3d_env.training import cli as training_cli

    made = []
    monkeypatch.setattr(training_cli, "train_policy", lambda cfg, overwrite: made.append(cfg) or {"ok": True})
    old = ["--conf-file", "ppo", "--learning-rate", "1e-3", "--gamma", "0.95", "--normalize", "--out", "runs/a"]
    new = ["ppo", "--hyperparams", "learning_rate=1e-3", "gamma=0.95", "normalize=true", "--out", "runs/a"]
    code, _, err = _train_policy_command(old, capsys)
    assert code == 0
    assert "--learning-rate is deprecated on 2026-12-06" in err and "--hyperparams learning_rate=VALUE" in err
    assert "--conf-file is deprecated on 2026-12-06" in err
    assert _train_policy_command(new, capsys)[0] == 0
    assert made[0] == made[1] and made[0].learning_rate == 1e-3 and made[0].gamma == 0.95
    assert made[0].total_steps == 8_000_000  # the recipe's, untouched


def test_the_learning_rate_falls_linearly_to_its_final_value(tmp_path):
    """``learning_rate_final``: each round of updates uses the rate of its progress through
    ``total_steps`` (as the logger records it), from ``learning_rate`` towards the final rate."""
    cfg = TrainConfig(algo="ppo", total_steps=512, n_steps=128, batch_size=64, learning_rate=1e-3,
                      learning_rate_final=1e-4, out=str(tmp_path), **{**FAST, "eval_freq": 0, "checkpoint_freq": 0})
    train_policy(cfg)
    with open(tmp_path / "progress.csv") as f:
        rows = [r for r in csv.DictReader(f) if r.get("train/learning_rate")]
    steps = np.array([float(r["time/total_timesteps"]) for r in rows])
    rates = np.array([float(r["train/learning_rate"]) for r in rows])
    # A round follows each 128-step rollout at the rate of the progress made; SB3 logs a round's
    # rate with the next rollout's row (the last round, at the final rate, goes unlogged).
    assert len(rates) == 3 and rates == pytest.approx(1e-3 + (1e-4 - 1e-3) * (steps - 128) / 512)
    with pytest.raises(ValueError, match="learning_rate_final"):
        TrainConfig(learning_rate_final=0.0)


def test_a_wall_schedule_is_trained_with_saved_and_loaded(tmp_path):
    """``learning_rate_by_wall``: the run's model carries the wall-aware schedule through
    ``model.save``/``PPO.load``; loading for acting does not need it at all."""
    from stable_baselines3 import PPO

    from sms3d_env.training import WallAwareLinearSchedule

    cfg = TrainConfig(algo="ppo", total_steps=128, n_steps=128, batch_size=64, learning_rate=1e-3,
                      learning_rate_final=1e-4, learning_rate_by_wall=True, max_wall_s=3600.0,
                      out=str(tmp_path), **{**FAST, "eval_freq": 0, "checkpoint_freq": 0})
    train_policy(cfg)
    loaded = PPO.load(str(tmp_path / "model.zip"), device="cpu")
    assert isinstance(loaded.learning_rate, WallAwareLinearSchedule)
    assert loaded.lr_schedule(1.0) == pytest.approx(1e-3, rel=1e-3)
    assert loaded.lr_schedule(0.0) == pytest.approx(1e-4)
    # Loading for acting never unpickles the schedule: it gets SB3's constant default instead.
    assert isinstance(load_model(tmp_path / "model.zip").learning_rate, float)


def test_eval_rejects_bad_arguments(tmp_path):
    with pytest.raises(FileNotFoundError):
        evaluate_policy_success(tmp_path / "missing.zip", episodes=1)
    with pytest.raises(ValueError, match="episodes"):
        evaluate_policy_success(tmp_path / "missing.zip", episodes=0)


def test_cli_registers_subcommands(capsys):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    a = parser.parse_args(["train-policy", "ppo", "--steps", "300", "--n-envs", "2", "--pose-error-deg", "10",
                           "--out", "runs/x", "--seed", "3", "--num-mushrooms", "8", "--eval-episodes", "4"])
    assert (a.recipe, a.steps, a.n_envs, a.pose_error_deg, a.seed, a.num_mushrooms, a.eval_episodes) == \
        ("ppo", 300, 2, 10.0, 3, [8], 4)
    assert callable(a.func)
    b = parser.parse_args(["eval-policy", "--model", "m.zip", "--eval-episodes", "30",
                           "--pose-error-deg", "30"])
    assert (b.episodes, b.pose_error_deg) == (30, 30.0) and callable(b.func)
    bad = parser.parse_args(["train-policy", "ppo", "--n-envs", "0"])
    assert bad.func(bad) == 2
    assert "--n-envs: TrainConfig.n_envs must be an integer >= 1" in capsys.readouterr().out


def test_train_policy_keeps_the_flags_a_user_sets_by_hand():
    """Recipes are data: ``--help`` lists at most 25 flags (the rest is the recipe's, or
    ``--hyperparams``)."""
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    train = parser._subparsers._group_actions[0].choices["train-policy"]
    shown = [a for a in train._actions if a.help != argparse.SUPPRESS and a.option_strings]
    assert len(shown) <= 25, [a.option_strings for a in shown]


def test_module_main_eval_policy(ppo_run, tmp_path, capsys):
    from sms3d_env.training import main

    out = tmp_path / "res.json"
    assert main(["eval-policy", "--model", str(ppo_run[0] / "model.zip"), "--episodes", "1",
                 "--json", str(out)]) == 0
    assert json.loads(out.read_text())["episodes"] == 1
    assert main(["eval-policy", "--model", str(tmp_path / "missing.zip")]) == 2


def test_a_run_starts_from_a_checkpoint_of_another_and_a_checkpoint_evaluates_like_its_run(tmp_path):
    """``init_model``: a checkpoint's weights and observation statistics become the new run's
    start; a checkpoint alone is rebuilt with its run's env (config.json one folder up)."""
    import numpy as np

    from sms3d_env.pickers.policy import PolicyActor
    from sms3d_env.policies.files import ObservationStats
    from sms3d_env.policies.loader import observation_stats_path, saved_config_path
    from sms3d_env.training.envs import normalized, vec_env
    from sms3d_env.training.rl import InitModelError, _build_model, _start_from

    first = tmp_path / "first"
    cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v2", total_steps=128, n_steps=128, batch_size=64,
                      normalize=True, out=str(first), **{**FAST, "eval_freq": 0})
    train_policy(cfg)
    checkpoint = first / "checkpoints" / "ppo_128_steps.zip"
    assert saved_config_path(checkpoint) == first / "config.json"
    # The statistics of the final model and of each checkpoint as arrays, none as a pickle.
    assert (first / "obs_rms.npz").is_file() and not list(first.rglob("*.pkl"))
    assert observation_stats_path(checkpoint) == first / "checkpoints" / "ppo_obs_rms_128_steps.npz"
    actor = PolicyActor(checkpoint)
    assert actor.env_id == "SMS3DPickTrain-v2" and actor.obs_stats is not None

    again = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "second"), "init_model": str(checkpoint)})
    env = normalized(vec_env(again.env_kwargs(), 1, 0, None), training=True)
    try:
        model = _build_model(again, env)
        _start_from(model, env, again)
        saved = load_model(checkpoint)
        for a, b in zip(model.policy.parameters(), saved.policy.parameters(), strict=True):
            assert np.array_equal(a.detach().numpy(), b.detach().numpy())
        stats = ObservationStats.load(observation_stats_path(checkpoint)).obs
        assert all(np.array_equal(env.obs_rms[k].mean, stats[k].mean) for k in stats)

        with pytest.raises(InitModelError, match="no saved model"):
            _start_from(model, env, TrainConfig(**{**again.__dict__, "init_model": str(tmp_path / "none.zip")}))
        wider = TrainConfig(**{**again.__dict__, "net_arch": (64, 64)})
        with pytest.raises(InitModelError, match="does not fit"):
            _start_from(_build_model(wider, env), env, wider)
    finally:
        env.close()
    # Refused before anything is written: continuing into the run's own folder, and dropping the
    # normalisation the weights were trained with.
    written = (first / "config.json").read_text()
    with pytest.raises(InitModelError, match="output folder"):
        train_policy(TrainConfig(**{**again.__dict__, "out": str(first), "total_steps": 1_000_000}))
    assert (first / "config.json").read_text() == written
    with pytest.raises(InitModelError, match="normalize=True"):
        train_policy(TrainConfig(**{**again.__dict__, "normalize": False}))
    assert not (tmp_path / "second").exists()
    # Weights that do not fit the network are found by building it before the run folder is
    # opened: nothing is written, and with --overwrite the old run survives the refusal.
    with pytest.raises(InitModelError, match="does not fit"):
        train_policy(TrainConfig(**{**again.__dict__, "net_arch": (64, 64)}))
    assert not (tmp_path / "second").exists()
    earlier = tmp_path / "earlier"  # a run folder that --overwrite would empty
    earlier.mkdir()
    (earlier / "run_settings.json").write_text("{}")
    (earlier / "model.zip").write_bytes(b"old")
    with pytest.raises(InitModelError, match="does not fit"):
        train_policy(TrainConfig(**{**again.__dict__, "out": str(earlier), "net_arch": (64, 64)}), overwrite=True)
    assert (earlier / "model.zip").read_bytes() == b"old"
    with pytest.raises(ValueError, match="init_model"):
        TrainConfig(algo="sac", init_model=str(checkpoint))



def test_a_flat_observation_run_in_the_training_process_acts_on_dict_observations(tmp_path):
    """``vec_env="dummy"`` + ``flat_observation``: two envs in this process, an MlpPolicy on the
    flattened observation; ``PolicyActor`` builds the usual dict-observation env and flattens
    each observation as training did (gymnasium's order, saved as ``observation_keys``)."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    from sms3d_env.pickers.policy import PolicyActor
    from sms3d_env.policies.envs import make_env
    from sms3d_env.training.envs import vec_env

    cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v2", n_envs=2, vec_env="dummy", flat_observation=True,
                      normalize=True, total_steps=256, n_steps=64, batch_size=64, out=str(tmp_path),
                      **{**FAST, "checkpoint_freq": 0})
    venv = vec_env(cfg.env_kwargs(), 2, 0, None, cfg.vec_env)
    try:
        assert isinstance(venv, DummyVecEnv) and venv.num_envs == 2
    finally:
        venv.close()
    train_policy(cfg)
    model = load_model(tmp_path / "model.zip")
    assert type(model.policy).__name__ == "ActorCriticPolicy"  # MlpPolicy, not MultiInputActorCriticPolicy
    actor = PolicyActor(tmp_path / "model.zip")
    bed = {"scene": {"placement": {"num_mushrooms": 8}}}
    env, flat_env = actor.make_env(**bed), make_env("SMS3DPickTrain-v2", flat_observation=True, **bed)
    try:
        obs, _ = env.reset(seed=3)
        flat, _ = flat_env.reset(seed=3)
        assert isinstance(obs, dict) and flat.shape == model.observation_space.shape
        stats = actor.obs_stats
        np.testing.assert_array_equal(flat, gym.spaces.flatten(env.observation_space, obs))
        expected, _ = model.predict(stats.normalize_obs(flat), deterministic=True)
        np.testing.assert_array_equal(actor(obs), expected)
    finally:
        env.close()
        flat_env.close()
    _check_eval(tmp_path / "model.zip")


def test_normalised_rewards_are_scaled_by_the_discounted_returns_spread(tmp_path):
    from sms3d_env.policies.files import ObservationStats

    cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v2", n_envs=2, vec_env="dummy", flat_observation=True,
                      normalize=True, normalize_reward=True, total_steps=256, n_steps=64, batch_size=64,
                      out=str(tmp_path), **{**FAST, "checkpoint_freq": 0})
    train_policy(cfg)
    stats = ObservationStats.load(tmp_path / "obs_rms.npz")
    assert stats.norm_reward and stats.gamma == cfg.gamma and stats.returns.count > 256
    assert json.loads((tmp_path / "config.json").read_text())["normalize_reward"] is True
    with pytest.raises(ValueError, match="normalize_reward needs normalize"):
        TrainConfig(normalize_reward=True)


def test_a_run_cannot_start_from_a_model_of_the_other_observation_layout(ppo_run, tmp_path):
    out, _ = ppo_run  # dict observations
    cfg = TrainConfig(algo="ppo", total_steps=128, n_steps=128, batch_size=64, flat_observation=True,
                      init_model=str(out / "model.zip"), out=str(tmp_path), **FAST)
    with pytest.raises(InitModelError, match="dict observations.*flat_observation=False"):
        train_policy(cfg)
