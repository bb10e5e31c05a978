"""The critic warm-up: PPO's actor takes no update until the warm-up steps are collected, its
critic does, and the actor trains again afterwards."""

from __future__ import annotations

import argparse
import csv

import gymnasium as gym
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sms3d_env.training import TrainConfig, register, train_policy
from sms3d_env.training.warmup import actor_parameters, critic_warmup


class LinearFeatures(BaseFeaturesExtractor):
    """A features extractor with parameters of its own."""

    def __init__(self, observation_space: gym.Space) -> None:
        super().__init__(observation_space, features_dim=4)
        self.linear = torch.nn.Linear(observation_space.shape[0], 4)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return self.linear(observations)


def _ppo(**policy_kwargs):
    from stable_baselines3 import PPO

    return PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=128, batch_size=64, n_epochs=2,
               policy_kwargs={"net_arch": [16, 16], **policy_kwargs}, seed=0, device="cpu", verbose=0)


def _snapshot(params) -> list[torch.Tensor]:
    return [p.detach().clone() for p in params]


def _changed(before, params) -> bool:
    return any(not torch.equal(b, p.detach()) for b, p in zip(before, params, strict=True))


def _critic_parameters(policy) -> list[torch.nn.Parameter]:
    return [*policy.value_net.parameters(), *policy.mlp_extractor.value_net.parameters()]


class ActorAtRolloutStart(BaseCallback):
    """The actor's parameters as each rollout starts (i.e. after the update before it)."""

    def __init__(self) -> None:
        super().__init__()
        self.snapshots: list[list[torch.Tensor]] = []

    def _on_rollout_start(self) -> None:
        self.snapshots.append(_snapshot(actor_parameters(self.model.policy)))

    def _on_step(self) -> bool:
        return True


def test_the_critic_learns_while_the_actor_is_frozen():
    model = _ppo()
    actor = actor_parameters(model.policy)
    critic = _critic_parameters(model.policy)
    actor0, critic0 = _snapshot(actor), _snapshot(critic)
    model.learn(256, callback=critic_warmup(1_000))
    assert not _changed(actor0, actor)
    assert _changed(critic0, critic)
    # Released when training ends: a model trained further from here has a trainable actor.
    assert all(p.requires_grad for p in actor)


def test_the_updates_on_the_warmup_steps_leave_the_actor_and_the_next_train_it():
    model = _ppo()
    actor = actor_parameters(model.policy)
    seen = ActorAtRolloutStart()
    model.learn(256, callback=CallbackList([critic_warmup(128), seen]))  # two rollouts of 128 steps
    first, second = seen.snapshots
    assert not _changed(first, second)  # the first update: the critic alone
    assert _changed(second, actor)  # the second: the actor too


def test_actor_and_critic_parameters_partition_the_policy():
    policy = _ppo().policy
    actor = {id(p) for p in actor_parameters(policy)}
    critic = {id(p) for p in _critic_parameters(policy)}
    assert id(policy.log_std) in actor
    assert not actor & critic
    assert actor | critic == {id(p) for p in policy.parameters()}


def test_an_actor_with_its_own_features_extractor_freezes_it_and_a_shared_one_is_refused():
    policy = _ppo(features_extractor_class=LinearFeatures, share_features_extractor=False).policy
    actor = {id(p) for p in actor_parameters(policy)}
    assert {id(p) for p in policy.pi_features_extractor.parameters()} <= actor
    assert not {id(p) for p in policy.vf_features_extractor.parameters()} & actor
    with pytest.raises(ValueError, match="shared by actor and critic"):
        actor_parameters(_ppo(features_extractor_class=LinearFeatures).policy)


@pytest.mark.parametrize("steps", [0, -5, 2.5, True])
def test_bad_warmup_lengths_are_refused(steps):
    with pytest.raises(ValueError, match="warm-up steps"):
        critic_warmup(steps)


def test_a_pick_run_logs_its_frozen_actor(tmp_path):
    cfg = TrainConfig(algo="ppo", env_id="SMS3DPickTrain-v0", residual_scale=0.5, normalize=True,
                      critic_warmup_steps=128, total_steps=256, n_steps=128, batch_size=64, out=str(tmp_path),
                      num_mushrooms=8, max_episode_steps=40, eval_freq=0, checkpoint_freq=0, verbose=0,
                      net_arch=(32, 32))
    train_policy(cfg)
    with open(tmp_path / "progress.csv", newline="") as f:
        frozen = [float(r["train/actor_frozen"]) for r in csv.DictReader(f) if r.get("train/actor_frozen")]
    assert frozen == [1.0, 0.0]


@pytest.mark.parametrize("recipe", ["rl", "residual"])
def test_the_flag_reaches_the_training_config(monkeypatch, recipe):
    from sms3d_env.training import cli

    seen = []
    monkeypatch.setattr(cli, "train_policy", lambda cfg, overwrite: seen.append(cfg) or {})
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="cmd"))
    a = parser.parse_args(["train-policy", "--recipe", recipe, "--critic-warmup-steps", "4096"])
    assert a.func(a) == 0
    assert seen[0].critic_warmup_steps == 4096
