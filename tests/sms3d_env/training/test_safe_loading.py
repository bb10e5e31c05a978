"""Loading a policy file never runs code from it: every model the package saves and loads (PPO and
SAC, dict and flattened observations, the shipped features extractor, gSDE, a falling rate)
loads with no unpickler called and acts as the saved model did; the shipped policies act as SB3's
own loader makes them act; crafted pickled entries never run."""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import zipfile

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO, SAC

from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.policies.features import NormalizedFlatten
from sms3d_env.policies.files import (
    POLICY_SPEC_MEMBER,
    PolicyFileError,
    record_policy_spec,
    save_model,
)
from sms3d_env.policies.loader import SHIPPED_POLICY, load_model, load_sb3
from sms3d_env.training.schedules import falling_rate


def no_unpickling(monkeypatch) -> None:
    """From now on in the test, any unpickling fails it (SB3 unpickles its entries with
    cloudpickle.loads, its replay buffers with pickle.load)."""
    def refuse(*_args, **_kwargs):
        raise AssertionError("something was unpickled")

    for module in (pickle, cloudpickle):
        monkeypatch.setattr(module, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)


class _DictEnv(gym.Env):
    """A small dict-observation env (one bound infinite, as the pick env's are), episodes of 8 steps."""

    observation_space = gym.spaces.Dict({"b": gym.spaces.Box(-1, 1, (2,)), "a": gym.spaces.Box(0, np.inf, (3,))})
    action_space = gym.spaces.Box(-1, 1, (2,))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.observation_space.sample(), {}

    def step(self, action):
        self.t += 1
        return self.observation_space.sample(), float(-np.sum(np.square(action))), False, self.t >= 8, {}


def _bc_model():
    """As ``imitation.build_policy_model`` builds the shipped policies: NormalizedFlatten with statistics."""
    kwargs = {"net_arch": [16], "log_std_init": -2.0, "features_extractor_class": NormalizedFlatten,
              "features_extractor_kwargs": {"mean": [0.1, 0.2, 0.3, 0.0, -0.5], "std": [1.0, 2.0, 0.5, 1.0, 3.0]}}
    return PPO("MultiInputPolicy", _DictEnv(), n_steps=16, batch_size=16, n_epochs=1, policy_kwargs=kwargs,
               seed=0, device="cpu")


def _flat_sde_model():
    """A flat-observation PPO with gSDE and a falling rate (pickled in the zip)."""
    return PPO("MlpPolicy", "Pendulum-v1", n_steps=16, batch_size=16, n_epochs=1, use_sde=True,
               learning_rate=falling_rate(3e-4, 3e-5), policy_kwargs={"net_arch": [16], "log_std_init": -1.0},
               seed=0, device="cpu")


def _sac_model(policy, env):
    """A SAC with a small buffer."""
    return SAC(policy, env, learning_starts=8, buffer_size=64, batch_size=8, policy_kwargs={"net_arch": [16]},
               seed=0, device="cpu")


MODELS = {"ppo bc": _bc_model, "ppo flat gsde": _flat_sde_model,
          "sac dict": lambda: _sac_model("MultiInputPolicy", _DictEnv()),
          "sac flat": lambda: _sac_model("MlpPolicy", "Pendulum-v1")}


def _observations(space, n=32):
    space.seed(1)
    if isinstance(space, gym.spaces.Dict):
        return {k: np.stack([s.sample() for _ in range(n)]) for k, s in space.spaces.items()}
    return np.stack([space.sample() for _ in range(n)])


@pytest.mark.parametrize("name", MODELS)
def test_a_saved_model_loads_with_nothing_unpickled_and_acts_as_saved(tmp_path, name, monkeypatch):
    model = MODELS[name]()
    model.learn(16)  # a trained model's zip also pickles its last observations and episode records
    save_model(model, tmp_path / "model.zip")
    with zipfile.ZipFile(tmp_path / "model.zip") as z:
        pickled = [k for k, v in json.loads(z.read("data")).items() if isinstance(v, dict) and ":serialized:" in v]
    assert {"policy_class", "observation_space", "action_space", "_last_obs"} <= set(pickled)
    no_unpickling(monkeypatch)
    loaded = load_sb3(tmp_path / "model.zip", ("ppo", "sac"))
    assert type(loaded) is type(model)
    assert loaded.observation_space == model.observation_space and loaded.action_space == model.action_space
    obs = _observations(model.observation_space)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


def test_the_shipped_policy_acts_as_sb3s_own_loader_made_it(monkeypatch):
    """SB3's own loader is used here on the project's shipped files only, as the reference."""
    for path in (SHIPPED_POLICY,):
        reference = PPO.load(str(path), device="cpu")
        with monkeypatch.context() as m:
            no_unpickling(m)
            actor = PolicyActor(path)
        env = actor.make_env(scene={"placement": {"num_mushrooms": 8}})
        try:
            for seed in range(3):
                obs, _ = env.reset(seed=seed)
                for _ in range(5):
                    action = actor(obs)
                    np.testing.assert_array_equal(action, reference.predict(obs, deterministic=True)[0])
                    obs, *_ = env.step(action)
        finally:
            env.close()
        obs = {k: np.clip(v, -5, 5) for k, v in _observations(reference.observation_space, 64).items()}
        np.testing.assert_array_equal(actor.model.predict(obs, deterministic=True)[0],
                                      reference.predict(obs, deterministic=True)[0])


class _Payload:
    """Unpickling it creates a file (what a hostile pickle could do, harmlessly)."""

    def __init__(self, path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _rewrite(src, dst, data=None, spec=None, drop_spec=False):
    """``src``'s zip with its ``data`` JSON and policy spec changed by the given functions."""
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w") as b:
        for name in a.namelist():
            content = a.read(name)
            if name == "data" and data is not None:
                content = json.dumps(data(json.loads(content)))
            elif name == POLICY_SPEC_MEMBER:
                if drop_spec:
                    continue
                if spec is not None:
                    content = json.dumps(spec(json.loads(content)))
            b.writestr(name, content)


def test_crafted_pickled_entries_never_run(tmp_path):
    marker = tmp_path / "ran"
    payload = {":type:": "<class 'object'>", ":serialized:": base64.b64encode(pickle.dumps(_Payload(marker))).decode()}
    cloudpickle.loads(base64.b64decode(payload[":serialized:"]))  # the payload is live: unpickled, it runs
    assert marker.exists()
    marker.unlink()
    shutil.copy(SHIPPED_POLICY, tmp_path / "shipped.zip")

    # Entries the loader rebuilds: SB3 gets its values instead, and the file loads.
    crafted = tmp_path / "replaced.zip"
    _rewrite(tmp_path / "shipped.zip", crafted,
             data=lambda d: {**d, **{k: payload for k in ("policy_class", "observation_space", "action_space",
                                                           "policy_kwargs", "lr_schedule", "clip_range", "_last_obs")}})
    shipped = load_model(SHIPPED_POLICY)
    obs = {k: np.clip(v, -5, 5) for k, v in _observations(shipped.observation_space).items()}
    np.testing.assert_array_equal(load_model(crafted).predict(obs, deterministic=True)[0],
                                  shipped.predict(obs, deterministic=True)[0])
    # An entry it does not know is refused by name; an env named in the data too.
    for key, value, match in [("evil", payload, "pickled entry 'evil'"), ("env", "CartPole-v1", "SB3's save leaves out")]:
        _rewrite(tmp_path / "shipped.zip", crafted, data=lambda d, key=key, value=value: {**d, key: value})
        with pytest.raises(PolicyFileError, match=match):
            load_model(crafted)
    # Without the policy's description nothing is unpickled either: the file is refused.
    _rewrite(tmp_path / "shipped.zip", crafted, data=lambda d: {**d, "evil": payload}, drop_spec=True)
    with pytest.raises(PolicyFileError, match=f"holds no {POLICY_SPEC_MEMBER}.*record_policy_spec"):
        load_model(crafted)
    assert not marker.exists()


@pytest.mark.parametrize("change, field", [
    (lambda s: {**s, "policy_kwargs": {**s["policy_kwargs"], "features_extractor_class": "os.system"}},
     "features_extractor_class"),
    (lambda s: {**s, "policy": "CnnPolicy"}, "policy"),
    (lambda s: {**s, "action_space": {**s["action_space"], "low": [-1.0]}}, "action_space.low"),
    (lambda s: {**s, "observation_space": {"type": "Dict", "spaces": [["a", {"type": "Box", "dtype": "object"}]]}},
     "observation_space.spaces\\['a'\\]"),
])
def test_a_bad_policy_description_is_refused_naming_the_file_and_field(tmp_path, change, field):
    bad = tmp_path / "model.zip"
    _rewrite(SHIPPED_POLICY, bad, spec=change)
    with pytest.raises(PolicyFileError, match=f"{bad}: .*{field}"):
        load_model(bad)


def test_a_model_saved_without_a_description_loads_once_recorded_with_its_weights_untouched(tmp_path, monkeypatch):
    model = PPO("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [16]}, device="cpu")
    model.save(tmp_path / "model.zip")  # SB3's own save: no policy description
    with pytest.raises(PolicyFileError, match=f"{tmp_path / 'model.zip'}: holds no {POLICY_SPEC_MEMBER}"):
        load_sb3(tmp_path / "model.zip", ("ppo",))
    with zipfile.ZipFile(tmp_path / "model.zip") as z:
        before = {n: z.read(n) for n in z.namelist()}
    record_policy_spec(tmp_path / "model.zip")
    with zipfile.ZipFile(tmp_path / "model.zip") as z:
        assert {n: z.read(n) for n in z.namelist() if n != POLICY_SPEC_MEMBER} == before
    with pytest.raises(PolicyFileError, match=f"already holds {POLICY_SPEC_MEMBER}"):
        record_policy_spec(tmp_path / "model.zip")
    no_unpickling(monkeypatch)
    with pytest.raises(PolicyFileError, match="is a PPO model, not SAC"):
        load_sb3(tmp_path / "model.zip", ("sac",))
    obs = _observations(model.observation_space)
    np.testing.assert_array_equal(load_sb3(tmp_path / "model.zip", ("ppo",)).predict(obs, deterministic=True)[0],
                                  model.predict(obs, deterministic=True)[0])
