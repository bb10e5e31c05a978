"""``sms3d record-demos``: a picker's episodes recorded as a Minari dataset
(:mod:`sms3d_env.training.demonstrations`)."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

from sms3d_env.training.envs import POSTURE_TARGETS, TRAIN_ENV_ID, check_bed_size, env_kwargs

#: The ids the scripted picker records on: the training id (the observation the bc recipe clones)
#: and the base id.
RECORD_ENV_IDS = (TRAIN_ENV_ID, "SMS3DPick-v2", "SMS3DPickTrain-v1", "SMS3DPick-v1")
RECORD_POSE_SOURCES = ("oracle", "noisy", "perception")


def _check_args(args: Any) -> str | None:
    """The first argument that cannot be used, as ``argument --flag: why``; None if all can."""
    for flag, value, least in (("--episodes", args.episodes, 1), ("--seed", args.seed, 0)):
        if value < least:
            return f"argument {flag}: must be an integer >= {least}, got {value}"
    try:
        check_bed_size("num_mushrooms", args.num_mushrooms)
    except ValueError as e:
        return f"argument --num-mushrooms: {e}"
    for flag, value in (("--action-noise", args.action_noise), ("--pose-error-deg", args.pose_error_deg)):
        if not (math.isfinite(value) and value >= 0):
            return f"argument {flag}: must be a finite number >= 0, got {value}"
    if args.pose_error_range is not None:
        low, high = args.pose_error_range
        if not 0 <= low <= high <= 180:
            return f"argument --pose-error-range: needs 0 <= LOW <= HIGH <= 180, got {low} {high}"
        if args.pose_error_deg > 0:
            return "argument --pose-error-range: excludes --pose-error-deg"
    noisy = args.pose_error_deg > 0 or args.pose_error_range is not None
    if noisy and args.pose_source not in (None, "noisy"):
        return f"argument --pose-source: a pose error needs the noisy source, got {args.pose_source}"
    return None


def _env_and_expert(args: Any, spec: Any) -> tuple[Any, Any]:
    """The env to record (its kwargs JSON, so that the dataset rebuilds it) and what builds the
    expert on it."""
    import gymnasium as gym

    import sms3d_env  # noqa: F401  (registers the env ids)

    kw = env_kwargs(args.num_mushrooms, args.pose_error_deg,
                    None if args.pose_error_range is None else tuple(args.pose_error_range), args.posture_target)
    if args.pose_source == "perception":
        kw["pose_source"] = "perception"
    if spec.kind == "scripted":
        from sms3d_env.pickers.scripted import ScriptedPicker

        return gym.make(args.env_id or RECORD_ENV_IDS[0], **kw), ScriptedPicker.for_env
    from sms3d_env.pickers.policy import PolicyActor

    actor = PolicyActor(spec.model_path)
    if args.env_id is not None and args.env_id != actor.env_id:
        raise ValueError(f"--env-id {args.env_id}: the policy {spec.model_path} acts on {actor.env_id}")
    return actor.make_env(**kw), (lambda _env: actor)


def _cmd_record(args: Any) -> int:
    from sms3d_env.pickers.registry import parse_picker

    why = _check_args(args)
    if why is not None:
        print(f"error: {why}")
        return 2
    try:
        spec = parse_picker(args.picker)
        from sms3d_env.training.demonstrations import (
            check_dataset_id,
            check_not_namespace,
            check_recordable,
            dataset_path,
            datasets_root,
            record_datasets,
            replacing_dataset,
        )

        dataset_id = check_dataset_id(args.dataset_id)
        check_not_namespace(dataset_id)  # --overwrite deletes one dataset, never a namespace of them
        if dataset_path(dataset_id).exists() and not args.overwrite:
            print(f"error: argument --dataset-id: a Minari dataset {dataset_id!r} exists in {datasets_root()} "
                  "(MINARI_DATASETS_PATH); choose another id or pass --overwrite")
            return 2
        env, make_expert = _env_and_expert(args, spec)
        check_recordable(env)
    except (ValueError, TypeError, FileNotFoundError, ImportError) as e:  # PolicyFileError, DatasetError too
        print(f"error: {e}")
        return 2
    seeds = range(args.seed, args.seed + args.episodes)
    recording = {"picker": spec.label, "made_by": "sms3d record-demos"}
    try:
        # With --overwrite the earlier dataset stays until the new one is complete.
        with replacing_dataset(dataset_id):
            dataset, = record_datasets([(dataset_id, env)], make_expert, seeds, recording,
                                       action_noise=args.action_noise, desc=f"record-demos {dataset_id}")
    except ValueError as e:  # DatasetError: the env cannot be recorded
        print(f"error: {e}")
        return 2
    outcomes = list(dataset.storage.get_episode_metadata(dataset.episode_indices))
    successes = sum(bool(m["success"]) for m in outcomes)
    causes = Counter(str(m["failure_cause"]) for m in outcomes if not m["success"])
    print(f"{dataset_id}: {dataset.total_episodes} episodes, {dataset.total_steps} steps, success "
          f"{successes}/{len(outcomes)}; failures: {', '.join(f'{c} {n}' for c, n in sorted(causes.items())) or 'none'}")
    print(f"saved in {dataset_path(dataset_id)}; load with minari.load_dataset({dataset_id!r})")
    return 0


def register(subparsers: Any) -> None:
    """Add ``sms3d record-demos``."""
    p = subparsers.add_parser(
        "record-demos", help="record a picker's episodes as a Minari dataset (observations, executed actions, "
                             "the picker's labels; success and failure cause per episode)")
    p.add_argument("--dataset-id", required=True, metavar="ID",
                   help="Minari's (namespace/)name-v<N>, e.g. sms3d/pick-v2/scripted-v0; written under "
                        "MINARI_DATASETS_PATH (default ~/.minari/datasets)")
    p.add_argument("--overwrite", action="store_true",
                   help="delete an existing dataset of that id first (only that dataset: an id that names a "
                        "namespace of other datasets is refused)")
    p.add_argument("--episodes", type=int, default=50, help="episodes to record (failures included)")
    p.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i")
    p.add_argument("--picker", default="scripted",
                   help="scripted (default), policy (the shipped policy) or policy:PATH (a saved model.zip)")
    p.add_argument("--env-id", choices=RECORD_ENV_IDS, default=None,
                   help="the scripted picker's env (default SMS3DPickTrain-v2, the observation the bc recipe "
                        "clones); a policy records on its own")
    p.add_argument("--num-mushrooms", type=int, default=25, help="mushrooms per bed")
    p.add_argument("--pose-source", choices=RECORD_POSE_SOURCES, default=None,
                   help="default: noisy with a pose error, else oracle")
    p.add_argument("--pose-error-deg", type=float, default=0.0, help="the noisy source's orientation error")
    p.add_argument("--pose-error-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="an orientation error drawn per episode in [LOW, HIGH] degrees")
    p.add_argument("--posture-target", choices=POSTURE_TARGETS, default="estimate",
                   help="the env's IK posture (recorded with the env)")
    p.add_argument("--action-noise", type=float, default=0.0,
                   help="DART: Gaussian noise of this standard deviation on the executed twist; the clean "
                        "action stays the label (infos['expert_action'])")
    p.set_defaults(func=_cmd_record)
