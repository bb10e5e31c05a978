"""``sms3d train-policy``, ``sms3d eval-policy`` and ``sms3d learning-curve`` (also ``python -m
sms3d_env.training ...``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from generator.errors import ConfigError
from generator.files import write_atomic
from generator.run_folder import RunFolderError
from sms3d_env.episode_video import check_frame_size, claim_video_folder
from sms3d_env.policies.files import PolicyFileError
from sms3d_env.policies.spec import package_env_ids
from sms3d_env.training.config import (
    ALGOS,
    ENV_IDS,
    POSE_SOURCES,
    POSTURE_TARGETS,
    REWARD_TYPES,
    VEC_ENVS,
)
from sms3d_env.training.evaluation import evaluate_policy_success, success_line
from sms3d_env.training.recipes import ARTICLES, field_names
from sms3d_env.training.recipes import KINDS as RECIPE_KINDS
from sms3d_env.training.rl import InitModelError, train_policy
from sms3d_env.training.zoo import RecipeError

#: What the training commands raise, before writing anything, for input they cannot use.
INPUT_ERRORS = (InitModelError, RunFolderError, PolicyFileError)


def _summary_or_refusal(run: Callable[[], dict[str, Any]]) -> int:
    """A training command's last step: run it and print its summary (exit 0), or its refusal of an
    input it cannot use (exit 2)."""
    try:
        summary = run()
    except INPUT_ERRORS as e:
        print(f"error: {e}")
        return 2
    print(json.dumps(summary, indent=2))
    return 0


#: ``sms3d train-policy`` flags that set a recipe's field: flag dest → field name.
FIELD_FLAGS = {"out": "out", "seed": "seed", "env_id": "env_id", "steps": "total_steps", "max_wall_s": "max_wall_s",
               "n_envs": "n_envs", "vec_env": "vec_env", "num_mushrooms": "num_mushrooms",
               "scene_pool": "scene_pool", "pose_error_deg": "pose_error_deg",
               "pose_error_range": "pose_error_range_deg", "init_model": "init_model", "demos": "demos",
               "eval_freq": "eval_freq", "eval_episodes": "eval_episodes", "checkpoint_freq": "checkpoint_freq"}
#: Flags that set a field before recipes were data, deprecated on 2026-12-06 (removed after 2027-06-06):
#: flag → (field, argparse keywords). They still work, with a warning naming the replacement.
DEPRECATED_FIELD_FLAGS: dict[str, tuple[str, dict[str, Any]]] = {
    "--algo": ("algo", {"choices": ALGOS}),
    "--normalize": ("normalize", {"action": "store_const", "const": True}),
    "--normalize-reward": ("normalize_reward", {"action": "store_const", "const": True}),
    "--flat-observation": ("flat_observation", {"action": "store_const", "const": True}),
    "--pose-source": ("pose_source", {"choices": POSE_SOURCES}),
    "--log-std-init": ("log_std_init", {"type": float}),
    "--reward-type": ("reward_type", {"choices": REWARD_TYPES}),
    "--posture-target": ("posture_target", {"choices": POSTURE_TARGETS}),
    "--pregrasp-start": ("pregrasp_start", {"type": float}),
    "--pregrasp-anneal": ("pregrasp_anneal", {"action": "store_const", "const": True}),
    "--gamma": ("gamma", {"type": float}),
    "--learning-rate": ("learning_rate", {"type": float}),
    "--learning-rate-final": ("learning_rate_final", {"type": float}),
    "--learning-rate-by-wall": ("learning_rate_by_wall", {"action": "store_const", "const": True}),
    "--target-kl": ("target_kl", {"type": float}),
    "--demo-episodes": ("episodes", {"type": int}),
    "--demo-mushrooms": ("num_mushrooms", {"type": int, "nargs": "+"}),
    "--action-noise": ("action_noise", {"type": float}),
    "--epochs": ("epochs", {"type": int}),
    "--dagger-rounds": ("dagger_rounds", {"type": int}),
    "--dagger-episodes": ("dagger_episodes", {"type": int}),
}
#: Flags of options removed on 2026-12-06 because the runs that used them measured worse
#: (CHANGELOG.md); refused by name rather than as unknown arguments.
REMOVED_FLAGS = {"--critic-warmup-steps": 1, "--time-limit-terminal": 0, "--use-sde": 0, "--sde-sample-freq": 1}
DEPRECATION = "deprecated on 2026-12-06, removed after 2027-06-06"


def _dest(flag: str) -> str:
    return "legacy_" + flag.lstrip("-").replace("-", "_")


def _recipe_of(args: Any) -> Any:
    """The recipe that ``args`` names, with the fields its flags and ``--hyperparams`` set
    (``RecipeError`` or ``FileNotFoundError`` naming what it cannot use)."""
    import sys

    from sms3d_env.training.recipes import default_recipe, parse_hyperparams, read_recipe

    named = [(flag, value) for flag, value in (("RECIPE", args.recipe), ("--recipe", args.legacy_recipe),
                                               ("--conf-file", args.legacy_conf_file)) if value is not None]
    if not named:
        raise RecipeError("name a recipe: sms3d train-policy ppo (PPO from scratch), pick_policy (the shipped "
                          "policy's behaviour cloning) or a recipe file (docs/training.md)")
    if len(named) > 1 and not (len(named) == 2 and named[1][0] == "--conf-file" and args.legacy_recipe == "rl"):
        raise RecipeError(f"{' and '.join(flag for flag, _ in named)} both name a recipe; give one")
    for flag, _ in named:
        if flag != "RECIPE":
            print(f"warning: {flag} is {DEPRECATION}: name the recipe first, sms3d train-policy "
                  f"{'RECIPE_FILE' if flag == '--conf-file' else 'RECIPE'}", file=sys.stderr)
    flag, value = named[-1]
    recipe = default_recipe(value) if flag == "--recipe" else read_recipe(value)
    given: list[tuple[str, str, Any]] = []  # (flag, field, value), applied in this order
    for old, (field, _) in DEPRECATED_FIELD_FLAGS.items():
        value = getattr(args, _dest(old))
        if value is not None:
            print(f"warning: {old} is {DEPRECATION}: set {field} in the recipe or with --hyperparams "
                  f"{field}=VALUE", file=sys.stderr)
            given.append((old, field, value))
    given += [(f"--{dest.replace('_', '-')}", field, getattr(args, dest)) for dest, field in FIELD_FLAGS.items()
              if getattr(args, dest) is not None]
    article = ARTICLES[recipe.kind]
    for flag, field, value in given:
        if field not in field_names(recipe.kind):
            raise RecipeError(f"{flag}: {article} {recipe.kind} recipe has no {field} "
                              f"(its fields: {', '.join(field_names(recipe.kind))})")
        values = {field: value}
        if field == "num_mushrooms" and recipe.kind != "bc":
            if len(value) != 1:
                raise RecipeError(f"{flag}: {article} {recipe.kind} recipe trains on one bed size, got {value}")
            values[field] = value[0]
        if field in ("pose_error_deg", "pose_error_range_deg") and recipe.kind != "bc" and value \
                and not args.legacy_pose_source:
            values["pose_source"] = "noisy"  # the error needs the noisy pose source
        recipe = recipe.with_fields(values, flag)
    return recipe.with_fields(parse_hyperparams(args.hyperparams), "--hyperparams")


def _cmd_train(args: Any) -> int:
    removed = [flag for flag in REMOVED_FLAGS if getattr(args, _dest(flag)) is not None]
    if removed:
        print(f"error: {', '.join(removed)}: removed on 2026-12-06, the runs that used "
              f"{'them' if len(removed) > 1 else 'it'} measured worse (CHANGELOG.md); sms3d-pick 0.1.0 still has "
              f"{'them' if len(removed) > 1 else 'it'}")
        return 2
    try:
        recipe = _recipe_of(args)
    except (ValueError, FileNotFoundError) as e:  # RecipeError names the file or flag and the key
        print(f"error: {e}")
        return 2
    if recipe.kind != "bc":
        return _summary_or_refusal(lambda: train_policy(recipe.config, overwrite=args.overwrite))
    from sms3d_env.training.demonstrations import DatasetError
    from sms3d_env.training.imitation import NonFiniteLossError, train_bc

    try:
        return _summary_or_refusal(lambda: train_bc(recipe.config, overwrite=args.overwrite))
    except (DatasetError, ImportError) as e:  # a --demos dataset it cannot use; Minari missing
        print(f"error: {e}")
        return 2
    except NonFiniteLossError as e:  # the training diverged; the run is left unfinished
        print(f"error: {e}")
        return 1


def _cmd_eval(args: Any) -> int:
    if args.json is not None and (not str(args.json).strip() or Path(args.json).is_dir()):
        print(f"error: argument --json: must name a file to write, got {args.json!r}")
        return 2
    try:
        if args.video is not None:
            check_frame_size(tuple(args.video_size))
            claim_video_folder(args.video, args.overwrite)
        res = evaluate_policy_success(args.model, episodes=args.episodes, pose_error_deg=args.pose_error_deg,
                                      seed=args.seed, num_mushrooms=args.num_mushrooms, progress=True,
                                      video_dir=args.video, video_size=tuple(args.video_size), env_id=args.env_id)
    except ConfigError as e:  # an argument, named by its flag
        print(f"error: argument --{e.field.replace('_', '-')}: {e.message}")
        return 2
    except (ValueError, FileNotFoundError) as e:  # PolicyFileError names the file
        print(f"error: {e}")
        return 2
    text = json.dumps({k: v for k, v in res.items() if k != "per_episode"}, indent=2)
    print(text)
    print(success_line(res))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        write_atomic(args.json, json.dumps(res, indent=2))
    return 0


def register(subparsers: Any) -> None:
    """Add ``sms3d train-policy``, ``sms3d eval-policy`` and ``sms3d learning-curve``."""
    import argparse

    p = subparsers.add_parser(
        "train-policy", help="train a pick policy from a recipe (PPO from scratch, the shipped policy's behaviour "
                             "cloning, or a recipe file)",
        description="Train a pick policy from a recipe: a shipped one by name (ppo: PPO from scratch on "
                    "SMS3DPickTrain-v1; pick_policy: the shipped policy's behaviour cloning + DAgger) or a YAML "
                    "file (an RL Baselines3 Zoo hyperparameter file, or a mapping of `recipe: rl|bc` "
                    "and config fields; a run's config.json is one). The flags below replace the recipe's "
                    "fields; --hyperparams replaces any other.")
    p.add_argument("recipe", nargs="?", default=None, metavar="RECIPE",
                   help="a shipped recipe (ppo, pick_policy) or a recipe file")
    p.add_argument("--out", default=None,
                   help="run folder (model.zip, config.json, progress.csv, ...); a rerun with the same settings "
                        "resumes it from its latest checkpoint, other settings are refused (see --overwrite)")
    p.add_argument("--overwrite", action="store_true",
                   help="empty --out and start anew when it holds a run made with other settings")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--env-id", choices=ENV_IDS, default=None, help="rl: the env to train on")
    p.add_argument("--steps", type=int, default=None, help="rl: total env steps")
    p.add_argument("--max-wall-s", type=float, default=None,
                   help="rl: stop after this many seconds (after the current step)")
    p.add_argument("--n-envs", type=int, default=None, help="rl: envs stepped together (see --vec-env)")
    p.add_argument("--vec-env", choices=VEC_ENVS, default=None,
                   help="rl: subproc: one worker process per env; dummy: all envs in the training "
                        "process (no pipe round trip per step; leaves a core free)")
    p.add_argument("--num-mushrooms", type=int, nargs="+", default=None,
                   help="mushrooms per training bed (bc: the bed sizes its demonstrations cycle through)")
    p.add_argument("--scene-pool", type=int, default=None,
                   help="rl: draw training beds from a pool of this many (0: a new bed per reset)")
    p.add_argument("--pose-error-deg", type=float, default=None,
                   help="train under this orientation error of the pose estimate, degrees (0: exact poses)")
    p.add_argument("--pose-error-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="train under an orientation error drawn per episode in [LOW, HIGH] degrees")
    p.add_argument("--init-model", default=None, metavar="PATH",
                   help="rl (PPO): start from this saved model (model.zip, a checkpoint or "
                        "best/best_model.zip; its observation statistics too) instead of a fresh policy")
    p.add_argument("--demos", nargs="+", default=None, metavar="DATASET_ID",
                   help="bc: clone these Minari datasets (sms3d record-demos, on SMS3DPickTrain-v1; found under "
                        "MINARI_DATASETS_PATH) instead of recording demonstrations into --out/datasets")
    p.add_argument("--eval-freq", type=int, default=None,
                   help="rl: env steps between evaluations (0: none)")
    p.add_argument("--eval-episodes", type=int, default=None,
                   help="rl: episodes per periodic evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=None,
                   help="rl: env steps between checkpoints (0: none)")
    p.add_argument("--hyperparams", "--set", nargs="+", default=[], metavar="KEY=VALUE",
                   help="replace any other field of the recipe, e.g. learning_rate=1e-4 net_arch=[64,64] "
                        "(values read as YAML; the fields: docs/training.md; --set as in train-pose)")
    # Deprecated flags (hidden): they still work, with a warning naming the replacement.
    p.add_argument("--recipe", dest="legacy_recipe", choices=RECIPE_KINDS, default=None, help=argparse.SUPPRESS)
    p.add_argument("--conf-file", dest="legacy_conf_file", default=None, help=argparse.SUPPRESS)
    for flag, (_, kwargs) in DEPRECATED_FIELD_FLAGS.items():
        p.add_argument(flag, dest=_dest(flag), default=None, help=argparse.SUPPRESS, **kwargs)
    for flag, nargs in REMOVED_FLAGS.items():  # refused by name (_cmd_train)
        p.add_argument(flag, dest=_dest(flag), default=None, help=argparse.SUPPRESS,
                       **({"nargs": nargs} if nargs else {"action": "store_const", "const": True}))
    p.set_defaults(func=_cmd_train)

    e = subparsers.add_parser("eval-policy", help="success rate (95 %% Wilson interval) of a saved policy "
                                                  "(default: the shipped one)")
    e.add_argument("--model", default=None, help="path to model.zip (default: the shipped policy)")
    e.add_argument("--env-id", choices=package_env_ids(), default=None,
                   help="the env the model was trained on, where its files do not say it (a model saved by "
                        "SB3's own save; default: the one env whose spaces are the model's)")
    e.add_argument("--episodes", "--eval-episodes", dest="episodes", type=int, default=30)
    e.add_argument("--pose-error-deg", type=float, default=0.0, help="0: oracle poses")
    e.add_argument("--seed", type=int, default=1_000_000, help="first episode seed")
    e.add_argument("--num-mushrooms", type=int, default=None,
                   help="mushrooms per bed (default: the training bed size, else 25)")
    e.add_argument("--json", default=None, help="also write the result here")
    e.add_argument("--video", default=None, metavar="DIR",
                   help="also write each episode as DIR/episode_<seed>.mp4 (DIR holding none yet, see "
                        "--overwrite): the pick camera, the target "
                        "ringed, time and phase on every frame, the outcome and its cause at the end "
                        '(needs imageio-ffmpeg: pip install "sms3d-pick[video]")')
    e.add_argument("--video-size", type=int, nargs=2, default=[480, 640], metavar=("HEIGHT", "WIDTH"),
                   help="the videos' frame size in pixels, both even, at most the env's off-screen framebuffer "
                        "of 480 640 (the default)")
    e.add_argument("--overwrite", action="store_true",
                   help="with --video: delete the episode videos (episode_*.mp4) of an earlier run in DIR first; "
                        "without it such a folder is refused, so that two runs' videos never mix")
    e.set_defaults(func=_cmd_eval)

    from sms3d_env.training import learning_curve

    learning_curve.register(subparsers)


def main(argv: list[str] | None = None) -> int:
    """``python -m sms3d_env.training {train-policy,eval-policy,learning-curve} ...`` (same as ``sms3d ...``)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m sms3d_env.training")
    register(parser.add_subparsers(dest="cmd", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args))

