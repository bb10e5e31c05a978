"""Demonstrations as Minari datasets (Farama's format for offline RL and imitation): a picker's
episodes recorded through ``minari.DataCollector`` around the env (:func:`record_datasets`, used
by ``sms3d record-demos`` and the behaviour-cloning recipe), and read back as labelled steps
(:func:`labelled_steps`).

A dataset holds the episodes of one env spec (an env id and its keyword arguments: bed size,
pose source, options), so ``dataset.recover_environment()`` builds that env again. Each episode
has Minari's arrays: ``observations`` (the env's dict observation, ``T + 1`` rows per key),
``actions`` (``T × 7``: what the env executed), ``rewards``, ``terminations``, ``truncations``,
and ``infos`` with ``T + 1`` rows per key, row ``t`` belonging to ``observations[t]``:

=================  ============  ==========================================================
info               shape, dtype  meaning
=================  ============  ==========================================================
``expert_action``  (7,) float32  the picker's clean action for the observation: the label
``expert_acting``  bool          the picker acted in this episode (False: a DAgger episode,
                                 in which the clone acted and the picker only labelled)
``label_valid``    bool          the label is one to learn (False: a DAgger episode's states
                                 after the scripted picker, never having seen the seal it
                                 waited for, gave up and turned to lifting)
``is_success``     bool          the env's
``failure_cause``  str           the env's; ``""`` on success
=================  ============  ==========================================================

Why the label is an info and not the action: Minari's ``actions[t]`` is what took the env from
``observations[t]`` to ``observations[t + 1]``, which offline RL relies on. Collected DART-style
(``action_noise`` > 0) the executed action is the label plus noise, and in a DAgger episode the
clone acts, so ``actions`` stay what the env executed and the label is kept beside it. With the
picker acting without noise the two are equal.

Each episode's metadata (``dataset.storage.get_episode_metadata``) holds Minari's ``seed`` and
reward statistics, and ``success``, ``failure_cause`` and ``expert_acting``; the dataset's
metadata (``dataset.storage.metadata["recording"]``) says what made it: the picker, the pose
source, the seeds, the DART noise and the ``sms3d-pick`` version.

Minari is an optional dependency (``pip install "sms3d-pick[ecosystem]"``); it is imported when a
dataset is recorded or read. It finds datasets under ``MINARI_DATASETS_PATH`` (default
``~/.minari/datasets``); :func:`minari_root` points it at another folder for a while.

A recording caches its episodes in Minari's temporary folders until it writes the dataset; they
live in ``.recording.tmp<pid>`` under the datasets folder, which the next recording there removes
once that process is gone (a killed recording leaves no folder behind for long).
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import os
import shutil
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from generator.files import remove_orphaned_temporaries, temp_path

#: The key of the dataset metadata that says what recorded it.
RECORDING_KEY = "recording"
#: The distribution whose version a dataset records, and the author Minari's metadata names.
PACKAGE, PACKAGE_AUTHOR = "sms3d-pick", "SMS3D pick contributors"
#: The action's twist entries, which DART noise perturbs (the seventh, the tool command, stays clean).
TWIST_ENTRIES = 6
#: The folder (named by :func:`generator.files.temp_path`, so with the recording's pid) under the
#: datasets folder in which Minari's DataCollectors cache a recording's episodes.
RECORDING_CACHE = ".recording"
#: Observation entry ``suction[1]``: the vacuum sensor's seal flag (1 while a seal holds).
_SEAL_FLAG = ("suction", 1)


class DatasetError(ValueError):
    """A Minari dataset that cannot be used or made (missing, of another env, an id that
    exists); the message names the dataset id and the folder it was looked for in."""


def _minari() -> Any:
    try:
        import minari
    except ImportError as exc:
        raise ImportError('demonstrations are Minari datasets: pip install "sms3d-pick[ecosystem]" '
                          f"(missing: {exc.name})") from exc
    return minari


def datasets_root() -> Path:
    """Where Minari keeps datasets now: ``MINARI_DATASETS_PATH``, else (unset)
    ``~/.minari/datasets``. Minari takes a set but empty ``MINARI_DATASETS_PATH`` as set, not as
    unset (it reads datasets from the current folder and fails to record), so an empty one is
    refused (``DatasetError``) rather than read as the default, where Minari would not look."""
    value = os.environ.get("MINARI_DATASETS_PATH")
    if value is None:
        return Path.home() / ".minari" / "datasets"
    if not value.strip():
        raise DatasetError("MINARI_DATASETS_PATH is set but empty; set it to a folder, or unset it for Minari's "
                           "default ~/.minari/datasets")
    return Path(value)


@contextlib.contextmanager
def minari_root(folder: str | Path | None) -> Iterator[Path]:
    """Point Minari at ``folder`` (``None``: leave it) while the block runs: Minari takes its
    datasets folder only from ``MINARI_DATASETS_PATH``, read at each call."""
    if folder is None:
        yield datasets_root()
        return
    before = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(folder)
    try:
        yield Path(folder)
    finally:
        if before is None:
            del os.environ["MINARI_DATASETS_PATH"]
        else:
            os.environ["MINARI_DATASETS_PATH"] = before


def check_dataset_id(dataset_id: str) -> str:
    """``dataset_id`` if Minari takes it (``namespace/name-vN``, e.g. ``sms3d/pick-v2/scripted-v0``);
    ``ValueError`` naming it otherwise (its namespace, when only that is what Minari refuses)."""
    minari = _minari()
    dataset_id = str(dataset_id)
    try:
        _, _, version = minari.dataset.minari_dataset.parse_dataset_id(dataset_id)
    except (ValueError, TypeError):
        version = None
    if version is None:
        namespace = dataset_id.rpartition("/")[0]
        if namespace and not minari.namespace.NAMESPACE_REGEX.fullmatch(namespace):
            raise ValueError(f"dataset_id {dataset_id!r}: Minari refuses the namespace {namespace!r}; a namespace "
                             "has at least two characters, each a letter, digit, '-' or '_' (with '/' between "
                             "parts), e.g. sms3d/pick-v2/scripted-v0")
        raise ValueError(f"dataset_id must be Minari's (namespace/)name-v<version>, e.g. "
                         f"sms3d/pick-v2/scripted-v0; got {dataset_id!r}")
    return dataset_id


def dataset_path(dataset_id: str) -> Path:
    """The folder of ``dataset_id`` under :func:`datasets_root` (whether or not it exists)."""
    return datasets_root() / dataset_id


def check_not_namespace(dataset_id: str) -> None:
    """``DatasetError`` when the folder of ``dataset_id`` is a Minari namespace, one that holds
    other datasets (``sms3d/pick-v2`` beside ``sms3d/pick-v2/scripted-v0``), naming what it holds:
    an id of that name can be neither recorded nor deleted without them."""
    folder = dataset_path(dataset_id)
    if not folder.is_dir() or (folder / "data").is_dir():
        return
    held = sorted(str(p.parent.parent.relative_to(datasets_root())) for p in folder.rglob("data/metadata.json"))
    if held or (folder / "namespace_metadata.json").is_file():
        raise DatasetError(f"{dataset_id!r} is a Minari namespace in {datasets_root()}, not a dataset: it holds "
                           f"{', '.join(held) if held else 'no dataset yet'}; name a dataset of its own "
                           f"(e.g. {dataset_id}/NAME-v0)")


def recording_of(dataset_id: str) -> dict[str, Any] | None:
    """The ``recording`` metadata of a complete dataset made here (written last, so a dataset
    whose recording was cut short has none); ``None`` when there is no such dataset. Reads
    ``metadata.json`` as JSON: nothing in the dataset is unpickled."""
    path = dataset_path(dataset_id) / "data" / "metadata.json"
    try:
        metadata = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    recording = metadata.get(RECORDING_KEY) if isinstance(metadata, dict) else None
    return recording if isinstance(recording, dict) else None


def complete_datasets(root: str | Path) -> list[str]:
    """The ids of the complete datasets made here (:func:`recording_of`) under the Minari folder
    ``root``, sorted."""
    root = Path(root)
    if not root.is_dir():
        return []
    with minari_root(root):
        ids = sorted(str(p.parent.parent.relative_to(root)) for p in root.rglob("data/metadata.json"))
        return [i for i in ids if recording_of(i) is not None]


def open_dataset(dataset_id: str) -> Any:
    """``minari.load_dataset(dataset_id)`` from :func:`datasets_root` (never downloads);
    ``DatasetError`` naming the id and folder when it is not there."""
    minari = _minari()
    if not (dataset_path(dataset_id) / "data" / "metadata.json").is_file():
        raise DatasetError(f"no Minari dataset {dataset_id!r} in {datasets_root()} (MINARI_DATASETS_PATH); "
                           "record one with `sms3d record-demos`")
    return minari.load_dataset(dataset_id)


def with_true_target(env: Any, obs: dict[str, np.ndarray], target: int) -> dict[str, np.ndarray]:
    """``obs`` with the target's true cap top and stem axis in ``target_pose`` (the scripted picker
    reads nothing that depends on the estimate besides it; ``benchmarks/bench_tolerance_headroom.py``
    drives it so)."""
    inst = env.unwrapped.scene.instances[target]
    return {**obs, "target_pose": np.concatenate([np.asarray(inst.cap_top, float),
                                                  np.asarray(inst.rotation, float)[:, 2]])}


class ExpertLabels(gym.Wrapper):
    """Adds the expert's label of every observation to its ``info`` (``expert_action``,
    ``expert_acting``, ``label_valid``; see the module's table).

    ``make_expert(env)`` builds the expert at each reset: a callable ``obs -> action`` (the
    scripted picker, a saved policy). Set ``expert_acting`` before a reset to
    say who acts in that episode. The wrapper's spec is the env's: the labels belong to the
    recording, so a dataset's ``recover_environment()`` builds the env alone.
    """

    def __init__(self, env: gym.Env, make_expert: Callable[[gym.Env], Callable[..., np.ndarray]]) -> None:
        super().__init__(env)
        self.make_expert = make_expert
        self.expert_acting = True
        self.expert: Callable[..., np.ndarray] | None = None
        self._sealed = False

    @property
    def spec(self) -> Any:
        return self.env.spec

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.expert, self._sealed = self.make_expert(self.env), False
        return obs, self._labelled(obs, info)

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._labelled(obs, info)

    def _labelled(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        label = self.expert(obs)
        key, entry = _SEAL_FLAG
        self._sealed |= bool(obs[key][entry] > 0.5)
        valid = self.expert_acting or getattr(self.expert, "phase", None) != "lift" or self._sealed
        return {**info, "expert_action": np.asarray(label, np.float32), "expert_acting": bool(self.expert_acting),
                "label_valid": bool(valid)}


class _LabelledStep:
    """Minari's step-data callback: the step as Minari stores it, its info reduced to the
    module's table (Minari needs the same info keys, types and shapes at every step; the env's
    own info adds reward terms after the reset and holds lists)."""

    def __call__(self, env: Any, obs: Any, info: dict[str, Any], action: Any = None, rew: Any = None,
                 terminated: Any = None, truncated: Any = None) -> dict[str, Any]:
        return {"observation": obs, "action": action, "reward": rew, "terminated": terminated,
                "truncated": truncated,
                "info": {"expert_action": info["expert_action"], "expert_acting": info["expert_acting"],
                         "label_valid": info["label_valid"], "is_success": bool(info["is_success"]),
                         "failure_cause": info["failure_cause"] or ""}}


def _text(value: Any) -> str:
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


class _EpisodeOutcome:
    """Minari's episode-metadata callback: its reward statistics, plus the episode's ``success``,
    ``failure_cause`` and ``expert_acting``."""

    def __call__(self, episode: dict[str, Any]) -> dict[str, Any]:
        infos = episode["infos"]
        return {**_minari().EpisodeMetadataCallback()(episode), "success": bool(infos["is_success"][-1]),
                "failure_cause": _text(infos["failure_cause"][-1]), "expert_acting": bool(infos["expert_acting"][0])}


def pose_source_of(env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The pose source an env's keyword arguments set: ``pose_source`` and its ``pose_error_deg``
    (a number, or a drawn range as ``[low, high]``)."""
    return {"pose_source": env_kwargs.get("pose_source", "oracle"),
            **({"pose_error_deg": env_kwargs["pose_error_deg"]} if env_kwargs.get("pose_error_deg") else {})}


def recovered_env(dataset: Any) -> gym.Env:
    """The env ``dataset`` was recorded in, rebuilt from its env spec as Minari's
    ``recover_environment()`` does, but by the id's current registration and with the env options
    of earlier versions read as now (:func:`~sms3d_env.env_args.translate_legacy_options`), so that
    datasets recorded before the env's arguments were regrouped still rebuild their env."""
    from sms3d_env.env_args import translate_legacy_options

    spec = dataset.env_spec
    return gym.make(spec.id, max_episode_steps=spec.max_episode_steps, **translate_legacy_options(spec.kwargs))


def check_recordable(env: gym.Env) -> None:
    """``DatasetError`` unless ``env``'s spec is JSON (a dataset rebuilds its env from that), e.g.
    a pose source passed as an object instead of by name."""
    try:
        env.spec.to_json()
    except (TypeError, ValueError, AttributeError) as exc:
        kwargs = getattr(env.spec, "kwargs", {})
        raise DatasetError(f"the env {getattr(env.spec, 'id', env)} cannot be recorded: its keyword arguments "
                           f"{sorted(kwargs)} are not JSON ({exc}), so a dataset could not rebuild it; pass the "
                           "pose source by name (pose_error_deg=(low, high) for a drawn error), and every record "
                           "(scene, controller, start, ...) in its mapping form") from None


def record_datasets(targets: Sequence[tuple[str, gym.Env]], make_expert: Callable[[gym.Env], Callable[..., Any]],
                    seeds: Sequence[int], recording: dict[str, Any], *, actor: Callable[[Any], Any] | None = None,
                    beta: float = 1.0, action_noise: float = 0.0, rng: np.random.Generator | None = None,
                    desc: str = "recording", progress: bool = True) -> list[Any]:
    """Record episodes into new Minari datasets under :func:`datasets_root`, one per
    ``(dataset_id, env)`` of ``targets``: episode ``i`` runs ``reset(seed=seeds[i])`` in target
    ``i % len(targets)``. Returns the datasets, in the order of ``targets``.

    In each episode the expert acts with probability ``beta`` (DART: Gaussian noise of standard
    deviation ``action_noise`` on its six twist entries), else ``actor`` acts (DAgger); the
    expert labels every observation either way (:class:`ExpertLabels`). ``rng`` draws who acts
    and the noise (default: seeded by the first seed). Each dataset's metadata gets
    ``recording`` plus its env id, pose source, seeds, episode count, ``action_noise``, the
    expert's share of the episodes and the package version. The envs are closed at the end.
    ``DatasetError`` before anything runs for an id that exists or an env that cannot be
    recorded.
    """
    minari = _minari()
    from tqdm import tqdm

    for dataset_id, env in targets:
        check_dataset_id(dataset_id)
        check_recordable(env)
        check_not_namespace(dataset_id)
        if dataset_path(dataset_id).exists():
            raise DatasetError(f"a Minari dataset {dataset_id!r} exists in {datasets_root()}; choose another id or "
                               "delete it (sms3d record-demos --overwrite)")
    rng = np.random.default_rng(seeds[0] if len(seeds) else 0) if rng is None else rng
    labellers = [ExpertLabels(env, make_expert) for _, env in targets]
    root = datasets_root()
    remove_orphaned_temporaries(root)
    with minari_root(temp_path(root / RECORDING_CACHE)):  # where each DataCollector makes its cache
        collectors = [minari.DataCollector(labeller, step_data_callback=_LabelledStep,
                                           episode_metadata_callback=_EpisodeOutcome, record_infos=True)
                      for labeller in labellers]
    seeds_of: list[list[int]] = [[] for _ in targets]
    try:
        successes = 0
        bar = tqdm(seeds, desc=desc, disable=not progress, unit="ep")
        for i, seed in enumerate(bar):
            k = i % len(targets)
            labellers[k].expert_acting = actor is None or bool(rng.random() < beta)
            obs, info = collectors[k].reset(seed=int(seed))
            done = False
            while not done:
                if labellers[k].expert_acting:
                    act = info["expert_action"].copy()
                    act[:TWIST_ENTRIES] += rng.normal(0.0, action_noise, TWIST_ENTRIES).astype(np.float32)
                else:
                    act = np.asarray(actor(obs), np.float32)
                obs, _, terminated, truncated, info = collectors[k].step(np.clip(act, -1, 1).astype(np.float32))
                done = terminated or truncated
            seeds_of[k].append(int(seed))
            successes += bool(info["is_success"])
            bar.set_postfix(success=successes)
        version = importlib.metadata.version("sms3d-pick")
        datasets = []
        for (dataset_id, env), collector, made in zip(targets, collectors, seeds_of, strict=True):
            with warnings.catch_warnings():
                # The package publishes no code link or e-mail for Minari's optional fields.
                warnings.filterwarnings("ignore", message="`(code_permalink|author_email)` is set to None")
                dataset = collector.create_dataset(
                    dataset_id, eval_env=env.spec, algorithm_name=str(recording.get("picker", "unknown")),
                    author=PACKAGE_AUTHOR,
                    description=f"{len(made)} episodes of {env.spec.id} by {recording.get('picker', 'a picker')} "
                                "(observations, executed actions, the picker's labels in infos['expert_action'])",
                    requirements=[f"{PACKAGE}=={version}"])
            dataset.storage.update_metadata({RECORDING_KEY: {
                **recording, "env_id": env.spec.id, **pose_source_of(env.spec.kwargs), "episodes": len(made),
                "seeds": made, "action_noise": float(action_noise), "expert_share": 1.0 if actor is None else float(beta),
                "package": PACKAGE, "version": version}})
            datasets.append(dataset)
        return datasets
    finally:
        for collector in collectors:
            collector.close()
        shutil.rmtree(temp_path(root / RECORDING_CACHE), ignore_errors=True)


#: Where ``replacing_dataset`` keeps the dataset an overwrite replaces until the new one is
#: complete (under :func:`datasets_root`); a recording killed meanwhile leaves it there.
REPLACED_FOLDER = ".replaced"


@contextlib.contextmanager
def replacing_dataset(dataset_id: str) -> Iterator[None]:
    """Record ``dataset_id`` anew without losing the one it replaces if the recording fails: the
    old folder is moved aside (``REPLACED_FOLDER``) for the block, deleted when the block ends
    normally, moved back when it raises (an interrupt included). Never a namespace's folder."""
    check_not_namespace(dataset_id)
    folder = dataset_path(dataset_id)
    if not folder.exists():
        yield
        return
    aside = temp_path(datasets_root() / REPLACED_FOLDER / dataset_id)
    aside.parent.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(aside, ignore_errors=True)
    folder.rename(aside)
    try:
        yield
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)  # what the failed recording left
        aside.rename(folder)
        raise
    shutil.rmtree(aside, ignore_errors=True)
    for parent in aside.parents:  # the empty folders it was kept in
        if parent == datasets_root() or any(parent.iterdir()):
            break
        parent.rmdir()


def delete_dataset(dataset_id: str) -> None:
    """Remove ``dataset_id``'s folder under :func:`datasets_root` (a complete dataset or what a
    cut recording left); never a namespace's, which holds other datasets (``DatasetError``,
    :func:`check_not_namespace`)."""
    check_not_namespace(dataset_id)
    shutil.rmtree(dataset_path(dataset_id), ignore_errors=True)


def _refuse_non_finite(dataset: str, episode: int, field: str, values: Any) -> None:
    """``DatasetError`` naming the dataset, episode and field when ``values`` hold a NaN or an
    infinity (learnt from, one turns every weight NaN)."""
    values = np.asarray(values)
    if np.issubdtype(values.dtype, np.number) and not np.isfinite(values).all():
        rows = np.unique(np.nonzero(~np.isfinite(values))[0])
        raise DatasetError(f"dataset {dataset!r}, episode {episode}: {field} holds non-finite values (NaN or "
                           f"infinity) in {len(rows)} row(s), first row {int(rows[0])}; record it again "
                           "(sms3d record-demos) or leave it out")


def check_finite(dataset: Any) -> None:
    """``DatasetError`` naming the dataset, episode and field (``observations[KEY]``,
    ``actions``, ``infos[expert_action]``) of the first value in ``dataset`` that is not finite."""
    name = dataset.spec.dataset_id
    for ep in dataset.iterate_episodes():
        observations = ep.observations if isinstance(ep.observations, dict) else {"": ep.observations}
        for key, values in observations.items():
            _refuse_non_finite(name, ep.id, f"observations[{key!r}]" if key else "observations", values)
        _refuse_non_finite(name, ep.id, "actions", ep.actions)
        if "expert_action" in (ep.infos or {}):
            _refuse_non_finite(name, ep.id, "infos['expert_action']", ep.infos["expert_action"])


def labelled_steps(datasets: Sequence[Any], keys: Sequence[str]) -> dict[str, np.ndarray]:
    """The steps a clone learns from: per observation key in ``keys`` ``(steps, n)`` float32,
    ``actions`` ``(steps, 7)`` float32 (the ``expert_action`` labels) and ``episode`` ``(steps,)``
    (the kept episode's number, counted over the datasets in order). Episodes in which the expert acted and failed are dropped, and so
    are steps whose label is not valid; each episode's last observation, after its last action,
    has no step. ``DatasetError`` naming a dataset without the labels or the keys, or the
    episode and field of a step that is not finite."""
    obs_rows: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    labels: list[np.ndarray] = []
    episode: list[np.ndarray] = []
    for dataset in datasets:
        name = dataset.spec.dataset_id
        missing = sorted(set(keys) - set(getattr(dataset.observation_space, "spaces", {})))
        if missing:
            raise DatasetError(f"dataset {name!r} observes no {missing}: recorded on another env than "
                               f"the clone's (its env: {getattr(dataset.env_spec, 'id', None)})")
        for ep in dataset.iterate_episodes():
            infos = ep.infos
            if not {"expert_action", "expert_acting", "label_valid"} <= set(infos or {}):
                raise DatasetError(f"dataset {name!r} holds no expert labels in its infos: not recorded by "
                                   "sms3d record-demos")
            if infos["expert_acting"][0] and not infos["is_success"][-1]:
                continue
            steps = len(ep.actions)
            keep = np.asarray(infos["label_valid"][:steps], bool)
            for k in keys:
                _refuse_non_finite(name, ep.id, f"observations[{k!r}]", ep.observations[k][:steps])
                obs_rows[k].append(np.asarray(ep.observations[k][:steps][keep], np.float32))
            _refuse_non_finite(name, ep.id, "infos['expert_action']", infos["expert_action"][:steps])
            labels.append(np.asarray(infos["expert_action"][:steps][keep], np.float32))
            episode.append(np.full(int(keep.sum()), len(episode), np.int64))
    if not labels or not sum(len(a) for a in labels):
        ids = [d.spec.dataset_id for d in datasets]
        raise DatasetError(f"datasets {ids} hold no step to learn from (no successful expert episode)")
    out = {k: np.concatenate(v) for k, v in obs_rows.items()}
    out["actions"] = np.concatenate(labels)
    out["episode"] = np.concatenate(episode)
    return out
