"""``sms3d sweep`` and ``sms3d sweep-compare``."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from generator.dataset.errors import CorruptFileError
from generator.errors import ConfigError
from sms3d_env.pickers.registry import picker_name
from sms3d_env.study.compare import check_paired, compared_rows, picker_comparison
from sms3d_env.study.plan import DEFAULT_ERRORS_DEG, SENSITIVITY_VARIANTS, SweepConfig
from sms3d_env.study.report import write_report
from sms3d_env.study.resume import load_rows
from sms3d_env.study.sweep import BACKENDS, run_sweep


def _cmd_sweep(args: Any) -> int:
    import shlex
    import sys

    try:
        config = SweepConfig(
            errors_deg=tuple(args.errors), episodes=args.episodes, seed=args.seed,
            num_mushrooms=args.num_mushrooms, variants=tuple(args.variants), chunk=args.chunk,
            perception_episodes=args.perception_episodes, perception_detector=args.perception_detector,
            perception_realism=args.perception_realism, picker=args.picker, position_errors_mm=tuple(args.position_errors_mm),
            position_along_axis=args.position_along_axis, tools=tuple(args.tool), robots=tuple(args.robot),
            targets=tuple(args.target),
            env_kwargs={} if args.posture_target == "estimate" else {"controller": {"posture_target": args.posture_target}},
        )
    except ConfigError as exc:
        print(f"sms3d sweep: error: argument {SWEEP_FLAGS.get(exc.field, exc.field)}: {exc.message}", file=sys.stderr)
        return 2
    try:
        rows = run_sweep(config, args.out, workers=args.workers, backend=args.backend)
    except (ValueError, CorruptFileError, RuntimeError) as exc:
        print(f"sms3d sweep: error: {exc}", file=sys.stderr)
        return 2
    command = "sms3d " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["sweep"] else ""
    paths = write_report(rows, args.out, command)
    print(Path(paths["md"]).read_text(encoding="utf-8"))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def _cmd_compare(args: Any) -> int:
    import sys

    from sms3d_env.study.figures import check_figure_path, distinct_names
    from sms3d_env.study.report import plot_pickers

    try:
        check_figure_path(args.out)
        curves: dict[str, list[dict[str, Any]]] = {}
        sweeps = {}
        for folder, name in zip(args.sweeps, distinct_names(args.sweeps), strict=True):
            rows = compared_rows(load_rows(folder))
            if not rows:
                raise ValueError(f"{folder} holds no episodes of the noisy pose source with the default "
                                 "physics, the ones compared; rerun it with --variants default")
            label = picker_name(rows[0].get("picker", "scripted"))
            # Two sweeps of one picker (e.g. with other env options) keep both curves.
            label = label if label not in curves else f"{label} ({name})"
            curves[label], sweeps[folder] = rows, rows
        check_paired(sweeps)
    except (FileNotFoundError, CorruptFileError, ValueError) as exc:
        print(f"sms3d sweep-compare: error: {exc}", file=sys.stderr)
        return 2
    print(picker_comparison(curves))
    plot_pickers(curves, args.out)
    print(f"wrote {args.out}")
    return 0


# The flag that sets each field SweepConfig checks, to report a refused value by what was typed.
SWEEP_FLAGS = {"errors_deg": "--errors", "episodes": "--episodes", "chunk": "--chunk", "seed": "--seed",
               "position_errors_mm": "--position-errors-mm", "tools": "--tool", "robots": "--robot", "targets": "--target",
               "perception_episodes": "--perception-episodes", "variants": "--variants",
               "placement.num_mushrooms": "--num-mushrooms", "picker": "--picker"}


def register(subparsers: Any) -> None:
    """Add ``sms3d sweep``."""
    from sms3d_env.robots import registered_robots

    p = subparsers.add_parser("sweep", help="pick success of a picker against orientation and position error")
    p.add_argument("--out", required=True, help="output folder (resumes if it holds earlier parts)")
    p.add_argument("--errors", type=float, nargs="+", default=list(DEFAULT_ERRORS_DEG),
                   help="errors in degrees, each in [0, 180]")
    p.add_argument("--episodes", type=int, default=40, help="seeded episodes per error (>= 1, default 40)")
    p.add_argument("--seed", type=int, default=0, help="first episode seed (>= 0)")
    p.add_argument("--num-mushrooms", type=int, nargs="+", default=[25],
                   help="mushrooms per bed; several values make bed size an axis of the sweep")
    p.add_argument("--position-errors-mm", type=float, nargs="+", default=[0.0],
                   help="cap-top position errors (mm, exact, perpendicular to the estimated stem "
                        "axis) crossed with --errors: the 2-D map")
    p.add_argument("--position-along-axis", action="store_true",
                   help="offset the cap top along the estimated axis instead of across it")
    p.add_argument("--tool", nargs="+", default=["suction"], choices=["suction", "hand"],
                   help="tools to sweep (the scripted picker for each)")
    p.add_argument("--robot", nargs="+", default=list(SweepConfig.robots), choices=registered_robots(),
                   help="robots to sweep (registered names; several make the robot an axis: a robot column in "
                        "sweep.csv, a curve and a map per robot)")
    # The rules are checked by SweepConfig: the targets module imports MuJoCo, which `sms3d --help` must not.
    p.add_argument("--target", nargs="+", default=list(SweepConfig.targets),
                   help="target rules (which mushroom each episode picks: harvest_ready, the env's default; the "
                        "study's classes isolated, crowded, approach_blocked, small; or tallest, largest, random); "
                        "several make the target an axis, a curve and a map per rule")
    p.add_argument("--backend", choices=BACKENDS, default="process",
                   help="process pool (default) or Ray (same rows)")
    p.add_argument("--variants", nargs="+", default=["default"], choices=sorted(SENSITIVITY_VARIANTS),
                   help="physics settings to compare (sensitivity to unsourced assumptions)")
    p.add_argument("--perception-episodes", type=int, default=SweepConfig.perception_episodes,
                   help="also run this many episodes with the perception pose source (shipped segmenter and axis CNN)")
    p.add_argument("--perception-detector", default=SweepConfig.perception_detector,
                   help="stage 1 of the perception episodes: 'shipped' (the shipped RGB-D segmenter, default), "
                        "'oracle' (MuJoCo's segmentation masks) or a train-segmenter/train-detector checkpoint")
    p.add_argument("--perception-realism", action="store_true",
                   help="the perception episodes' overhead camera has every realism effect (stereo noise and "
                        "shadows, flying pixels, RGB noise, lighting, camera jitter; as `sms3d generate --realism`)")
    p.add_argument("--picker", default=SweepConfig.picker,
                   help="scripted (default), policy (the shipped policy) or policy:PATH/model.zip; every "
                        "picker sees the same seeded episodes")
    p.add_argument("--posture-target", choices=("estimate", "tool"), default="estimate",
                   help="the env's IK posture (ControllerConfig.posture_target): estimate (default) or tool; "
                        "a learned picker's own recorded option wins")
    p.add_argument("--chunk", type=int, default=SweepConfig.chunk, help="episodes per resumable task (>= 1)")
    p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 1)), help="processes")
    p.set_defaults(func=_cmd_sweep)

    c = subparsers.add_parser("sweep-compare", help="one figure of several sweeps' pickers (success vs error)")
    c.add_argument("sweeps", nargs="+", help="sweep folders (each run with its own --picker, on the same "
                                             "--num-mushrooms, --seed, --episodes and --errors)")
    c.add_argument("--out", required=True, help="PNG to write")
    c.set_defaults(func=_cmd_compare)
