"""``sms3d train-policy`` and ``eval-policy`` as commands: an RL recipe becomes RL Baselines3 Zoo's
command line, a bc recipe its config; what a recipe cannot use is refused by name."""

from __future__ import annotations

import argparse

import pytest

from sms3d_env.training import cli as training_cli
from sms3d_env.training import evaluate_policy_success, register
from sms3d_env.training.zoo import recipe_path


def _train_policy_command(argv, capsys):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    a = parser.parse_args(["train-policy", *argv])
    code = a.func(a)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("argv, flag", [
    (["pick_policy", "--steps", "5"], "--steps: a bc recipe takes no such flag"),
    (["pick_policy", "--init-model", "runs/x/model.zip"], "--init-model: a bc recipe takes no such flag"),
    (["ppo", "--demos", "sms3d/pick-v2/x-v0"], "--demos: an rl recipe takes no such flag"),
    (["ppo", "--num-mushrooms", "10", "--overwrite"], "--num-mushrooms, --overwrite: an rl recipe takes no such flags"),
    (["ppo", "--epochs", "3"], "--epochs: an rl recipe takes no such flag"),
    (["ppo", "--hyperparams", "learning_rate"], "--hyperparams 'learning_rate': must be KEY=VALUE"),
    (["pick_policy", "--hyperparams", "epochs=0"], "--hyperparams: BCConfig.epochs must be an integer >= 1"),
    (["pick_policy", "--hyperparams", "lr=1e-3"], "--hyperparams: no field lr in a bc recipe"),
    (["--recipe", "bc", "--demo-episodes", "0"], "BCConfig.episodes must be"),
    ([], "name a recipe"),
    (["no-such-recipe"], "no recipe file no-such-recipe (shipped recipes: pick_policy, ppo)"),
    (["ppo", "--learning-rate", "1e-3", "--normalize"],
     "--learning-rate (learning_rate), --normalize (normalize): removed in 0.2.0 with the package's own RL trainer"),
    (["ppo", "--max-wall-s", "60"], "--max-wall-s (the callback wall_clock_limit): removed in 0.2.0"),
    (["ppo", "--algo", "nope"], "--algo nope: not an RL Zoo algorithm"),
], ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_train_policy_refuses_what_its_recipe_cannot_use_by_name(capsys, argv, flag):
    code, out, _ = _train_policy_command(argv, capsys)
    assert code == 2 and flag in out, out


def test_an_rl_recipe_runs_rl_zoo_with_the_command_line_its_flags_say(monkeypatch, capsys):
    """The flags become RL Zoo's, the recipe file is passed as it stands, and the periodic
    evaluation runs on fresh beds from home: the recipe's env_kwargs without pool and start."""
    made = []
    monkeypatch.setattr("sms3d_env.training.zoo.train_zoo", lambda argv: made.append(argv) or {"ok": True})
    argv = ["ppo", "--env-id", "SMS3DPickTrain-v2", "--vec-env", "dummy", "--eval-freq", "100000",
            "--eval-episodes", "40", "--seed", "2", "--out", "runs/ppo", "--checkpoint-freq", "50000",
            "--hyperparams", "learning_rate=1e-4", "policy_kwargs={net_arch: [64, 64]}"]
    assert _train_policy_command(argv, capsys)[0] == 0
    assert made == [["--algo", "ppo", "--env", "SMS3DPickTrain-v2", "--conf-file", str(recipe_path("ppo")),
                     "--gym-packages", "sms3d_env", "--num-threads", "1", "--device", "cpu", "--seed", "2",
                     "--log-folder", "runs/ppo", "--vec-env", "dummy", "--eval-freq", "100000",
                     "--eval-episodes", "40", "--save-freq", "50000",
                     "--hyperparams", "learning_rate:0.0001", "policy_kwargs:{'net_arch': [64, 64]}",
                     "--eval-env-kwargs", "scene:{'placement': {'num_mushrooms': 10}}"]]


def test_deprecated_bc_flags_still_set_their_field_with_a_warning_naming_the_release(monkeypatch, capsys):
    """The flags that set a bc field before recipes were data still work: the same config as the
    recipe with ``--hyperparams``, and a warning naming the release and the field."""
    made = []
    monkeypatch.setattr("sms3d_env.training.imitation.train_bc", lambda cfg, overwrite: made.append(cfg) or {})
    old = ["--conf-file", "pick_policy", "--epochs", "3", "--dagger-rounds", "1", "--out", "runs/a"]
    new = ["pick_policy", "--hyperparams", "epochs=3", "dagger_rounds=1", "--out", "runs/a"]
    code, _, err = _train_policy_command(old, capsys)
    assert code == 0
    assert "--epochs is deprecated in 0.2.0 and removed after 2027-06-06" in err and "--hyperparams epochs=VALUE" in err
    assert "--conf-file is deprecated in 0.2.0" in err
    assert _train_policy_command(new, capsys)[0] == 0
    assert made[0] == made[1] and (made[0].epochs, made[0].dagger_rounds, made[0].episodes) == (3, 1, 600)


def test_eval_rejects_bad_arguments(tmp_path):
    with pytest.raises(FileNotFoundError):
        evaluate_policy_success(tmp_path / "missing.zip", episodes=1)
    with pytest.raises(ValueError, match="episodes"):
        evaluate_policy_success(tmp_path / "missing.zip", episodes=0)


def test_cli_registers_subcommands():
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    a = parser.parse_args(["train-policy", "ppo", "--steps", "300", "--n-envs", "2", "--out", "runs/x",
                           "--seed", "3", "--eval-episodes", "4"])
    assert (a.recipe, a.steps, a.n_envs, a.seed, a.eval_episodes) == ("ppo", 300, 2, 3, 4)
    assert a.func is training_cli._cmd_train
    b = parser.parse_args(["eval-policy", "--model", "m.zip", "--eval-episodes", "30", "--pose-error-deg", "30"])
    assert (b.episodes, b.pose_error_deg) == (30, 30.0) and callable(b.func)


def test_train_policy_keeps_the_flags_a_user_sets_by_hand():
    """Recipes are data: ``--help`` lists at most 25 flags (the rest is the recipe's, or
    ``--hyperparams``)."""
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    train = parser._subparsers._group_actions[0].choices["train-policy"]
    shown = [a for a in train._actions if a.help != argparse.SUPPRESS and a.option_strings]
    assert len(shown) <= 25, [a.option_strings for a in shown]
