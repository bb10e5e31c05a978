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
from sms3d_env.training.envs import POSTURE_TARGETS
from sms3d_env.training.evaluation import evaluate_policy_success, success_line
from sms3d_env.training.zoo import RecipeError

#: What the training commands raise, before writing anything, for input they cannot use.
INPUT_ERRORS = (RunFolderError, PolicyFileError)
#: How a deprecated flag warns: the release that deprecated it and when it goes.
DEPRECATION = "deprecated in 0.2.0 and removed after 2027-06-06"


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


#: ``sms3d train-policy`` flags of RL recipes, by dest: each a keyword of ``zoo_argv`` (an RL Zoo flag).
RL_FLAGS = ("algo", "env_id", "steps", "n_envs", "vec_env", "eval_freq", "eval_episodes", "checkpoint_freq",
            "init_model")
#: Flags of bc recipes: flag dest → ``BCConfig`` field.
BC_FLAGS = {"num_mushrooms": "num_mushrooms", "pose_error_deg": "pose_error_deg",
            "pose_error_range": "pose_error_range_deg", "demos": "demos"}
#: Flags that set a bc recipe's field before recipes were data: flag → (field, argparse keywords).
#: They still work, with a warning naming the replacement.
DEPRECATED_BC_FLAGS: dict[str, tuple[str, dict[str, Any]]] = {
    "--demo-episodes": ("episodes", {"type": int}),
    "--demo-mushrooms": ("num_mushrooms", {"type": int, "nargs": "+"}),
    "--action-noise": ("action_noise", {"type": float}),
    "--epochs": ("epochs", {"type": int}),
    "--dagger-rounds": ("dagger_rounds", {"type": int}),
    "--dagger-episodes": ("dagger_episodes", {"type": int}),
    "--posture-target": ("posture_target", {"choices": POSTURE_TARGETS}),
}
#: Flags of the package's own RL trainer, which 0.2.0 replaced by RL Zoo's: refused by name, each
#: with the recipe key (or callback) that sets what it set.
RL_TRAINER_FLAGS = {
    "--learning-rate": "learning_rate", "--gamma": "gamma", "--target-kl": "target_kl", "--normalize": "normalize",
    "--normalize-reward": "normalize: {norm_reward: true}", "--log-std-init": "policy_kwargs: {log_std_init: ...}",
    "--flat-observation": "env_wrapper: gymnasium.wrappers.FlattenObservation", "--pose-source": "env_kwargs.pose_source",
    "--reward-type": "env_kwargs.reward_type", "--pregrasp-start": "env_kwargs.start.share",
    "--scene-pool": "env_kwargs.scene.pool", "--pregrasp-anneal": "the callback pregrasp_annealing",
    "--learning-rate-final": "the callback falling_learning_rate", "--learning-rate-by-wall": "its max_wall_s",
    "--max-wall-s": "the callback wall_clock_limit", "--use-sde": "use_sde", "--sde-sample-freq": "sde_sample_freq",
    "--critic-warmup-steps": "none: its runs measured worse", "--time-limit-terminal": "none: its runs measured worse",
}


def _dest(flag: str) -> str:
    return "legacy_" + flag.lstrip("-").replace("-", "_")


def _recipe_of(args: Any) -> Any:
    """The recipe that ``args`` names, with the bc fields its flags and ``--hyperparams`` set
    (``RecipeError`` or ``FileNotFoundError`` naming what it cannot use)."""
    import sys

    from sms3d_env.training.imitation import BCConfig
    from sms3d_env.training.recipes import Recipe, parse_hyperparams, read_recipe

    retired = [f"{flag} ({key})" for flag, key in RL_TRAINER_FLAGS.items() if getattr(args, _dest(flag)) is not None]
    if retired:
        raise RecipeError(f"{', '.join(retired)}: removed in 0.2.0 with the package's own RL trainer; an RL recipe "
                          "is an RL Baselines3 Zoo file: set that key in it (a copy of sms3d_env/recipes/ppo.yml) "
                          "or with --hyperparams KEY=VALUE (docs/training.md)")
    for flag, value in (("--recipe", args.legacy_recipe), ("--conf-file", args.legacy_conf_file)):
        if value is not None:
            print(f"warning: {flag} is {DEPRECATION}: name the recipe first, sms3d train-policy RECIPE", file=sys.stderr)
    name = args.recipe or args.legacy_conf_file
    if name is None and args.legacy_recipe == "bc":
        recipe = Recipe("bc", "the bc defaults", BCConfig())
    elif name is None:
        raise RecipeError("name a recipe: sms3d train-policy ppo (PPO from scratch, an RL Baselines3 Zoo file), "
                          "pick_policy (the shipped policy's behaviour cloning) or a recipe file (docs/training.md)")
    else:
        recipe = read_recipe(name, args.env_id)
    hyperparams = parse_hyperparams(args.hyperparams)
    mine, theirs = (BC_FLAGS, RL_FLAGS) if recipe.kind == "bc" else (RL_FLAGS, [*BC_FLAGS, "overwrite"])
    given = [f"--{d.replace('_', '-')}" for d in theirs if getattr(args, d) not in (None, False)]
    given += [flag for flag in DEPRECATED_BC_FLAGS if recipe.kind == "rl" and getattr(args, _dest(flag)) is not None]
    if given:
        raise RecipeError(f"{', '.join(given)}: {'an rl' if recipe.kind == 'rl' else 'a bc'} recipe takes no "
                          f"{'such flag' if len(given) == 1 else 'such flags'} (sms3d train-policy --help)")
    if recipe.kind == "rl":
        return recipe, hyperparams
    values: dict[str, Any] = {}
    for flag, (field, _) in DEPRECATED_BC_FLAGS.items():
        if getattr(args, _dest(flag)) is not None:
            print(f"warning: {flag} is {DEPRECATION}: set {field} in the recipe or with --hyperparams "
                  f"{field}=VALUE", file=sys.stderr)
            values[field] = getattr(args, _dest(flag))
    values.update({field: getattr(args, dest) for dest, field in {**BC_FLAGS, "out": "out", "seed": "seed"}.items()
                   if getattr(args, dest) is not None})
    return recipe.with_fields(values, "the command's flags").with_fields(hyperparams, "--hyperparams"), None


def _cmd_train(args: Any) -> int:
    try:
        recipe, hyperparams = _recipe_of(args)
    except (ValueError, FileNotFoundError) as e:  # RecipeError names the file or flag and the key
        print(f"error: {e}")
        return 2
    if recipe.kind == "rl":
        from sms3d_env.training.zoo import train_zoo, zoo_argv

        try:
            argv = zoo_argv(recipe.source, out=args.out or "logs", seed=args.seed or 0, hyperparams=hyperparams,
                            **{dest: getattr(args, dest) for dest in RL_FLAGS})
        except RecipeError as e:
            print(f"error: {e}")
            return 2
        except ImportError:
            print('error: an RL recipe runs RL Baselines3 Zoo\'s trainer: pip install "sms3d-pick[ecosystem]"')
            return 2
        return _summary_or_refusal(lambda: train_zoo(argv))
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
        "train-policy", help="train a pick policy from a recipe (PPO from scratch with RL Baselines3 Zoo, the "
                             "shipped policy's behaviour cloning, or a recipe file)",
        description="Train a pick policy from a recipe: a shipped one by name (ppo: PPO from scratch on "
                    "SMS3DPickTrain-v2, an RL Baselines3 Zoo file; pick_policy: the shipped policy's behaviour "
                    "cloning + DAgger) or a YAML file (an RL Baselines3 Zoo hyperparameter file, or a mapping of "
                    "`recipe: bc` and BCConfig fields; a bc run's config.json is one). An RL recipe runs RL Zoo's "
                    "trainer: the command prints the `python -m rl_zoo3.train` line it runs.")
    p.add_argument("recipe", nargs="?", default=None, metavar="RECIPE",
                   help="a shipped recipe (ppo, pick_policy) or a recipe file")
    p.add_argument("--out", default=None,
                   help="rl: RL Zoo's log folder (default logs; the run goes to OUT/ALGO/ENV_N); bc: the run folder "
                        "(model.zip, config.json, ...), which a rerun with the same settings resumes, other "
                        "settings refused (see --overwrite)")
    p.add_argument("--overwrite", action="store_true",
                   help="bc: empty --out and start anew when it holds a run made with other settings")
    p.add_argument("--seed", type=int, default=None, help="default 0")
    p.add_argument("--algo", default=None, help="rl: the algorithm (default: the recipe file's name, ppo for ppo.yml)")
    p.add_argument("--env-id", choices=package_env_ids(), default=None,
                   help="rl: the recipe file's entry to train (default: its first, SMS3DPickTrain-v2 in ppo)")
    p.add_argument("--steps", type=int, default=None, help="rl: total env steps (RL Zoo's -n)")
    p.add_argument("--n-envs", type=int, default=None, help="rl: envs stepped together")
    p.add_argument("--vec-env", choices=("dummy", "subproc"), default=None,
                   help="rl: dummy (RL Zoo's default): all envs in the training process; subproc: one worker "
                        "process per env")
    p.add_argument("--eval-freq", type=int, default=None,
                   help="rl: env steps between evaluations (RL Zoo's default 25000; 0: none)")
    p.add_argument("--eval-episodes", type=int, default=None, help="rl: episodes per evaluation (RL Zoo's default 5)")
    p.add_argument("--checkpoint-freq", type=int, default=None,
                   help="rl: env steps between checkpoints (RL Zoo's --save-freq; default none)")
    p.add_argument("--init-model", default=None, metavar="PATH",
                   help="rl: continue training this saved model (RL Zoo's --trained-agent, which SB3's own "
                        "loader unpickles: a file you trust)")
    p.add_argument("--num-mushrooms", type=int, nargs="+", default=None,
                   help="bc: the bed sizes the demonstrations cycle through")
    p.add_argument("--pose-error-deg", type=float, default=None,
                   help="bc: record the demonstrations under this orientation error of the pose estimate, degrees")
    p.add_argument("--pose-error-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="bc: under an orientation error drawn per episode in [LOW, HIGH] degrees")
    p.add_argument("--demos", nargs="+", default=None, metavar="DATASET_ID",
                   help="bc: clone these Minari datasets (sms3d record-demos, on SMS3DPickTrain-v2; found under "
                        "MINARI_DATASETS_PATH) instead of recording demonstrations into --out/datasets")
    p.add_argument("--hyperparams", "--set", nargs="+", default=[], metavar="KEY=VALUE",
                   help="replace a recipe's setting (values read as YAML): rl: any RL Zoo hyperparameter "
                        "(learning_rate=1e-4 policy_kwargs={net_arch: [64, 64]}); bc: any BCConfig field "
                        "(epochs=20; the fields: docs/training.md)")
    # Deprecated flags (hidden): they still work, with a warning naming the replacement.
    p.add_argument("--recipe", dest="legacy_recipe", choices=("rl", "bc"), default=None, help=argparse.SUPPRESS)
    p.add_argument("--conf-file", dest="legacy_conf_file", default=None, help=argparse.SUPPRESS)
    for flag, (_, kwargs) in DEPRECATED_BC_FLAGS.items():
        p.add_argument(flag, dest=_dest(flag), default=None, help=argparse.SUPPRESS, **kwargs)
    for flag in RL_TRAINER_FLAGS:  # refused by name (_recipe_of)
        p.add_argument(flag, dest=_dest(flag), nargs="?", const=True, default=None, help=argparse.SUPPRESS)
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

