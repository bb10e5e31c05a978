"""``sms3d train-policy``, ``sms3d train-trigger``, ``sms3d eval-policy`` and ``sms3d learning-curve`` (also
``python -m sms3d_env.training ...``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from generator.errors import ConfigError
from generator.files import write_atomic
from generator.run_folder import RunFolderError
from sms3d_env.training.config import (
    ALGOS,
    ENV_IDS,
    POSE_SOURCES,
    POSTURE_TARGETS,
    RECIPES,
    REWARD_TYPES,
    VEC_ENVS,
    TrainConfig,
)
from sms3d_env.training.evaluation import evaluate_policy_success, success_line
from sms3d_env.training.imitation import TEACHERS
from sms3d_env.training.model_files import PolicyFileError
from sms3d_env.training.rl import InitModelError, train_policy

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


def _cmd_train(args: Any) -> int:
    if args.conf_file is not None and args.recipe != "rl":
        print(f"error: --conf-file holds an rl recipe (PPO/SAC from scratch), not --recipe {args.recipe}")
        return 2
    if args.recipe == "bc":
        return _cmd_train_bc(args)
    noisy = args.pose_error_deg > 0 or args.pose_error_range is not None
    pose_source = args.pose_source or ("noisy" if noisy else "oracle")
    residual = args.recipe == "residual"
    for flag, given in (("--residual-until-held", args.residual_until_held),
                        ("--residual-approach-only", args.residual_approach_only),
                        ("--residual-descend-trigger", args.residual_descend_trigger),
                        ("--residual-trigger-only", args.residual_trigger_only)):
        if given and not residual:
            print(f"error: {flag} applies to --recipe residual")
            return 2
    try:
        cfg = TrainConfig(algo=args.algo, env_id="SMS3DPickTrain-v1" if residual else args.env_id,
                          normalize=args.normalize or residual, normalize_reward=args.normalize_reward,
                          scene_pool=args.scene_pool,
                          residual_scale=args.residual_scale if residual else 0.0,
                          residual_until_held=args.residual_until_held,
                          residual_approach_only=args.residual_approach_only,
                          residual_descend_trigger=args.residual_descend_trigger,
                          residual_trigger_only=args.residual_trigger_only,
                          trigger_log_std=args.trigger_log_std, trigger_log_std_final=args.trigger_log_std_final,
                          pose_error_range_deg=args.pose_error_range,
                          log_std_init=args.log_std_init if args.log_std_init is not None
                          else (-1.6 if residual else 0.0),
                          total_steps=args.steps, max_wall_s=args.max_wall_s,
                          n_envs=args.n_envs, vec_env=args.vec_env, flat_observation=args.flat_observation,
                          pose_source=pose_source, pose_error_deg=args.pose_error_deg,
                          reward_type=args.reward_type, num_mushrooms=args.num_mushrooms, seed=args.seed,
                          out=args.out, eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                          checkpoint_freq=args.checkpoint_freq, learning_rate=args.learning_rate,
                          learning_rate_final=args.learning_rate_final,
                          learning_rate_by_wall=args.learning_rate_by_wall,
                          target_kl=args.target_kl, posture_target=args.posture_target,
                          pregrasp_start=args.pregrasp_start, pregrasp_anneal=args.pregrasp_anneal,
                          init_model=args.init_model, critic_warmup_steps=args.critic_warmup_steps, gamma=args.gamma,
                          time_limit_terminal=args.time_limit_terminal, use_sde=args.use_sde,
                          sde_sample_freq=args.sde_sample_freq)
        if args.conf_file is not None:
            from sms3d_env.training.zoo import with_recipe

            cfg = with_recipe(cfg, args.conf_file)
    except (ValueError, FileNotFoundError) as e:  # RecipeError names the file and key
        print(f"error: {e}")
        return 2
    return _summary_or_refusal(lambda: train_policy(cfg, overwrite=args.overwrite))


def _cmd_train_bc(args: Any) -> int:
    from sms3d_env.training.imitation import BCConfig, train_bc

    # Options of the rl and residual recipes that behaviour cloning has no use for, and why.
    rl_only = {"--pregrasp-start": (args.pregrasp_start, "its demonstrations start at home"),
               "--pregrasp-anneal": (args.pregrasp_anneal, "its demonstrations start at home"),
               "--learning-rate-final": (args.learning_rate_final is not None, "its cloning uses a constant rate"),
               "--learning-rate-by-wall": (args.learning_rate_by_wall, "its cloning uses a constant rate"),
               "--init-model": (args.init_model, "it clones from scratch"),
               "--residual-until-held": (args.residual_until_held, "it trains no residual"),
               "--residual-approach-only": (args.residual_approach_only, "it trains no residual"),
               "--residual-descend-trigger": (args.residual_descend_trigger, "it trains no residual"),
               "--residual-trigger-only": (args.residual_trigger_only, "it trains no residual"),
               "--trigger-log-std": (args.trigger_log_std is not None, "it trains no residual"),
               "--trigger-log-std-final": (args.trigger_log_std_final is not None, "it trains no residual"),
               "--critic-warmup-steps": (args.critic_warmup_steps, "it trains no critic"),
               "--gamma": (args.gamma != TrainConfig().gamma, "it is trained on actions, not rewards"),
               "--time-limit-terminal": (args.time_limit_terminal, "it is trained on actions, not returns"),
               "--use-sde": (args.use_sde, "it explores nothing"),
               "--sde-sample-freq": (args.sde_sample_freq != -1, "it explores nothing"),
               "--normalize-reward": (args.normalize_reward, "it is trained on actions, not rewards"),
               "--vec-env": (args.vec_env != "subproc", "it collects its demonstrations in one env"),
               "--flat-observation": (args.flat_observation, "it clones a MultiInputPolicy")}
    for flag, (given, why) in rl_only.items():
        if given:
            print(f"error: {flag} applies to the rl and residual recipes (the bc recipe: {why})")
            return 2
    try:
        cfg = BCConfig(demos=tuple(args.demos), episodes=args.demo_episodes, epochs=args.epochs,
                       action_noise=args.action_noise,
                       pose_error_deg=args.pose_error_deg, pose_error_range_deg=args.pose_error_range,
                       teacher=args.teacher, posture_target=args.posture_target, seed=args.seed, out=args.out,
                       num_mushrooms=tuple(args.demo_mushrooms), dagger_rounds=args.dagger_rounds,
                       dagger_episodes=args.dagger_episodes)
    except ValueError as e:
        print(f"error: {e}")
        return 2
    from sms3d_env.training.demonstrations import DatasetError

    try:
        return _summary_or_refusal(lambda: train_bc(cfg, overwrite=args.overwrite))
    except (DatasetError, ImportError) as e:  # a --demos dataset it cannot use; Minari missing
        print(f"error: {e}")
        return 2


def _cmd_train_trigger(args: Any) -> int:
    from sms3d_env.training.trigger_rollouts import TriggerConfig, train_trigger

    try:
        cfg = TriggerConfig(out=args.out, episodes=args.episodes, seed=args.seed, num_mushrooms=args.num_mushrooms,
                            pose_error_range_deg=tuple(args.pose_error_range), posture_target=args.posture_target, robot=args.robot,
                            candidates=args.candidates, margin=args.margin, epochs=args.epochs,
                            workers=args.workers)
    except ValueError as e:
        print(f"error: {e}")
        return 2
    return _summary_or_refusal(lambda: train_trigger(cfg, overwrite=args.overwrite))


def _cmd_eval(args: Any) -> int:
    if args.json is not None and (not str(args.json).strip() or Path(args.json).is_dir()):
        print(f"error: argument --json: must name a file to write, got {args.json!r}")
        return 2
    try:
        res = evaluate_policy_success(args.model, episodes=args.episodes, pose_error_deg=args.pose_error_deg,
                                      seed=args.seed, num_mushrooms=args.num_mushrooms, progress=True,
                                      video_dir=args.video, video_size=tuple(args.video_size))
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
    from sms3d_env.robot_names import ROBOTS

    defaults = TrainConfig()
    p = subparsers.add_parser(
        "train-policy", help="train a pick policy: RL (PPO/SAC, stable-baselines3) or behaviour "
                             "cloning of the scripted picker (--recipe bc)")
    p.add_argument("--recipe", choices=RECIPES, default="rl",
                   help="rl: PPO/SAC from scratch (default); bc: scripted demonstrations -> "
                        "behaviour cloning on SMS3DPickTrain-v1 (sms3d_env.training.imitation); residual: "
                        "PPO/SAC on top of the scripted picker on SMS3DPickTrain-v1 (sms3d_env.training.residual)")
    p.add_argument("--conf-file", default=None, metavar="FILE",
                   help="rl: take the recipe from an RL Baselines3 Zoo hyperparameter file (the one rl_zoo3.train "
                        "--conf-file reads), or a shipped one by name (ppo: PPO from scratch); flags it sets must "
                        "be left out; --out, --seed, --eval-*, --checkpoint-freq and --vec-env stay flags")
    p.add_argument("--algo", choices=ALGOS, default=defaults.algo)
    p.add_argument("--env-id", choices=ENV_IDS, default=defaults.env_id,
                   help="SMS3DPickTrain-v1: the learnable options (latched suction, staged reward, ...)")
    p.add_argument("--normalize", action="store_true", help="standardise observations (VecNormalize)")
    p.add_argument("--normalize-reward", action="store_true",
                   help="rl/residual, with --normalize: also scale training rewards by the running std of the "
                        "discounted return (keeps the success step's value gradients from shrinking the policy's)")
    p.add_argument("--scene-pool", type=int, default=defaults.scene_pool,
                   help="draw training beds from a pool of this many (0: a new bed per reset)")
    p.add_argument("--steps", type=int, default=defaults.total_steps, help="total env steps")
    p.add_argument("--max-wall-s", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--n-envs", type=int, default=defaults.n_envs, help="parallel envs (see --vec-env)")
    p.add_argument("--vec-env", choices=VEC_ENVS, default=defaults.vec_env,
                   help="rl/residual: subproc (default): one worker process per env; dummy: all envs in the "
                        "training process (no pipe round trip per step; leaves a core free)")
    p.add_argument("--flat-observation", action="store_true",
                   help="rl/residual: flatten the dict observation into one vector and train an MlpPolicy on it "
                        "(the same inputs; less per-step overhead than MultiInputPolicy)")
    p.add_argument("--pose-source", choices=POSE_SOURCES, default=None,
                   help="default: noisy if --pose-error-deg > 0, else oracle")
    p.add_argument("--pose-error-deg", type=float, default=0.0)
    p.add_argument("--pose-error-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="train under a pose error drawn per episode in [LOW, HIGH] degrees")
    p.add_argument("--residual-scale", type=float, default=0.5,
                   help="--recipe residual: the residual's largest share of each command")
    p.add_argument("--residual-until-held", action="store_true",
                   help="--recipe residual: correct only the approach and touch-down; once the seal holds "
                        "the scripted picker's twist and lift run alone")
    p.add_argument("--residual-approach-only", action="store_true",
                   help="--recipe residual: correct only the approach to the stand-off point; the scripted "
                        "picker's descent, seal, twist and lift run alone")
    p.add_argument("--residual-descend-trigger", action="store_true",
                   help="--recipe residual: an eighth action entry that, above 0.5 within 2 cm of the stand-off "
                        "point, starts the scripted picker's descent from where the tool is (an escape from "
                        "approach stalls, learned); the observation gains the stand-off gap and the tool's "
                        "motion over the last 10 control steps")
    p.add_argument("--residual-trigger-only", action="store_true",
                   help="--residual-descend-trigger: the policy's action is the trigger alone; the scripted "
                        "picker's command runs unchanged (no continuous residual, so a trajectory changes only "
                        "where the trigger fires)")
    p.add_argument("--trigger-log-std", type=float, default=None, metavar="LOG_STD",
                   help="--residual-descend-trigger: the log standard deviation of the trigger's exploration "
                        "(default -0.9 for a fresh policy, an --init-model's own otherwise; lower: fewer chance "
                        "firings, so hesitating in a stall costs the episode)")
    p.add_argument("--trigger-log-std-final", type=float, default=None, metavar="LOG_STD",
                   help="--residual-descend-trigger: move the trigger's log standard deviation from "
                        "--trigger-log-std to this over the run (by steps or --max-wall-s, whichever ends first), "
                        "so that what the noisy policy fires by chance becomes what its mean fires")
    p.add_argument("--log-std-init", type=float, default=None,
                   help="initial log standard deviation of the policy (default 0; -1.6 for --recipe residual)")
    p.add_argument("--reward-type", choices=REWARD_TYPES, default=defaults.reward_type)
    p.add_argument("--out", default=defaults.out,
                   help="run folder (model.zip, progress.csv, ...); a rerun with the same settings resumes it "
                        "from its latest checkpoint, other settings are refused (see --overwrite)")
    p.add_argument("--overwrite", action="store_true",
                   help="empty --out and start anew when it holds a run made with other settings")
    p.add_argument("--seed", type=int, default=defaults.seed)
    p.add_argument("--num-mushrooms", type=int, default=defaults.num_mushrooms)
    p.add_argument("--eval-episodes", type=int, default=defaults.eval_episodes,
                   help="episodes per periodic evaluation")
    p.add_argument("--eval-freq", type=int, default=defaults.eval_freq, help="env steps between evaluations (0: none)")
    p.add_argument("--checkpoint-freq", type=int, default=defaults.checkpoint_freq,
                   help="env steps between checkpoints (0: none)")
    p.add_argument("--posture-target", choices=POSTURE_TARGETS, default="estimate",
                   help="the env's IK posture: estimate (default, solved once for the estimated axis) or "
                        "tool (re-solved as the tool turns; lets a picker correct a wrong estimate)")
    p.add_argument("--pregrasp-start", type=float, default=defaults.pregrasp_start, metavar="P",
                   help="rl/residual: the share of training episodes that start on the way from home to a pre-grasp "
                        "pose above the estimated target (a reverse curriculum; evaluation starts at home)")
    p.add_argument("--pregrasp-anneal", action="store_true",
                   help="rl/residual: lower that share as training episodes from home succeed: "
                        "P x (1 - success of the last 100 home starts), set after each rollout")
    p.add_argument("--gamma", type=float, default=defaults.gamma,
                   help="rl/residual: the discount factor (default %(default)s)")
    p.add_argument("--time-limit-terminal", action="store_true",
                   help="rl/residual on SMS3DPickTrain-v1: the time limit terminates episodes instead of "
                        "truncating them, so that PPO does not bootstrap the return there (the policy sees the "
                        "clock; an approach stalled until the limit then earns what it earned, not the critic's "
                        "guess of what would follow)")
    p.add_argument("--use-sde", action="store_true",
                   help="ppo: state-dependent exploration (gSDE): noise that stays the same while the state does, "
                        "redrawn every --sde-sample-freq steps; --log-std-init is then per weight of the noise map "
                        "(about exp(value) x 8 on each action for a trained 256-wide residual)")
    p.add_argument("--sde-sample-freq", type=int, default=defaults.sde_sample_freq, metavar="N",
                   help="with --use-sde: env steps between draws of the noise (default -1: once per rollout)")
    p.add_argument("--init-model", default=None, metavar="PATH",
                   help="rl/residual: start from this saved model (model.zip, a checkpoint or best/best_model.zip; "
                        "its observation statistics too with --normalize) instead of a fresh policy")
    p.add_argument("--learning-rate", type=float, default=defaults.learning_rate, help="rl/residual: the optimiser's rate")
    p.add_argument("--learning-rate-final", type=float, default=None, metavar="RATE",
                   help="rl/residual: fall linearly from --learning-rate to this by the last of --steps "
                        "(default: a constant rate)")
    p.add_argument("--learning-rate-by-wall", action="store_true",
                   help="rl/residual: let that fall run over whichever ends first, --steps or --max-wall-s "
                        "(so a run stopped by its wall limit ends at the final rate; needs "
                        "--learning-rate-final and --max-wall-s)")
    p.add_argument("--target-kl", type=float, default=None,
                   help="rl/residual with PPO: stop a round of updates once the KL from the rollout policy "
                        "passes 1.5 x this (default: no limit)")
    p.add_argument("--critic-warmup-steps", type=int, default=defaults.critic_warmup_steps, metavar="N",
                   help="rl/residual with PPO: freeze the actor for the first N env steps so that the critic "
                        "first learns the starting policy's returns (a residual's: the scripted picker's; "
                        "default 0: none)")
    bc = p.add_argument_group("behaviour cloning (--recipe bc)")
    bc.add_argument("--demos", nargs="+", default=[], metavar="DATASET_ID",
                    help="clone these Minari datasets (sms3d record-demos, on SMS3DPickTrain-v1; found under "
                         "MINARI_DATASETS_PATH) instead of recording demonstrations into --out/datasets")
    bc.add_argument("--demo-episodes", type=int, default=400, help="scripted episodes (failures dropped)")
    bc.add_argument("--demo-mushrooms", type=int, nargs="+", default=[10, 25], help="bed sizes cycled through")
    bc.add_argument("--action-noise", type=float, default=0.2, help="DART noise on the twist while collecting")
    bc.add_argument("--epochs", type=int, default=40, help="epochs of the first clone")
    bc.add_argument("--dagger-rounds", type=int, default=3, help="DAgger rounds after it (0: plain BC)")
    bc.add_argument("--dagger-episodes", type=int, default=150, help="episodes per DAgger round")
    bc.add_argument("--teacher", choices=TEACHERS, default="estimate",
                    help="estimate: the scripted picker labels from the observed pose; truth: from "
                         "the true pose (a privileged teacher under --pose-error-deg/--pose-error-range)")
    p.set_defaults(func=_cmd_train)

    from sms3d_env.training.trigger_rollouts import TriggerConfig

    tdef = TriggerConfig()
    t = subparsers.add_parser(
        "train-trigger", help="learn when to give up on the scripted approach and descend, from paired "
                              "counterfactual rollouts (a trigger-only residual; sms3d_env.training.trigger_rollouts)")
    t.add_argument("--out", default=tdef.out,
                   help="run folder (labels/, model.zip, config.json, summary.json); a rerun with the same "
                        "settings resumes it (--episodes may grow: the missing labels are collected), other "
                        "settings are refused (see --overwrite)")
    t.add_argument("--overwrite", action="store_true",
                   help="empty --out and start anew when it holds a run made with other settings")
    t.add_argument("--episodes", type=int, default=tdef.episodes, help="training episodes (one seed each)")
    t.add_argument("--seed", type=int, default=tdef.seed,
                   help="first episode seed (the study's held-out episodes start at 1000000)")
    t.add_argument("--num-mushrooms", type=int, default=tdef.num_mushrooms)
    t.add_argument("--pose-error-range", type=float, nargs=2, default=list(tdef.pose_error_range_deg),
                   metavar=("LOW", "HIGH"), help="orientation error drawn per episode in [LOW, HIGH] degrees")
    t.add_argument("--posture-target", choices=POSTURE_TARGETS, default=tdef.posture_target)
    t.add_argument("--robot", choices=ROBOTS, default=tdef.robot,
                   help="the robot the trigger learns to act on (SMS3DPick-v1's)")
    t.add_argument("--candidates", type=int, default=tdef.candidates,
                   help="most replays per episode, each firing the trigger at one step within its reach")
    t.add_argument("--margin", type=float, default=tdef.margin,
                   help="the expected gain in success probability the policy needs to fire")
    t.add_argument("--epochs", type=int, default=tdef.epochs, help="regression epochs")
    t.add_argument("--workers", type=int, default=tdef.workers, help="processes collecting the labels")
    t.set_defaults(func=_cmd_train_trigger)

    e = subparsers.add_parser("eval-policy", help="success rate (95 %% Wilson interval) of a saved policy "
                                                  "(default: the shipped one)")
    e.add_argument("--model", default=None, help="path to model.zip (default: the shipped policy)")
    e.add_argument("--episodes", "--eval-episodes", dest="episodes", type=int, default=30)
    e.add_argument("--pose-error-deg", type=float, default=0.0, help="0: oracle poses")
    e.add_argument("--seed", type=int, default=1_000_000, help="first episode seed")
    e.add_argument("--num-mushrooms", type=int, default=None,
                   help="mushrooms per bed (default: the training bed size, else 25)")
    e.add_argument("--json", default=None, help="also write the result here")
    e.add_argument("--video", default=None, metavar="DIR",
                   help="also write each episode as DIR/episode_<seed>.mp4: the pick camera, the target "
                        "ringed, time and phase on every frame, the outcome and its cause at the end "
                        '(needs imageio-ffmpeg: pip install "sms3d-pick[video]")')
    e.add_argument("--video-size", type=int, nargs=2, default=[480, 640], metavar=("HEIGHT", "WIDTH"),
                   help="the videos' frame size in pixels, both even (default 480 640)")
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

