"""``sms3d demo``: the whole project in one minute on embedded defaults.

Generates a seeded bed and renders it, runs the shipped two-stage perception on its overhead
RGB-D image (a picture of the masks and estimated stem axes), then lets the scripted pose-aware
picker pick with exact poses, with a 10-degree orientation error and with the poses perception
estimated from pixels, saving a picture of frames of each pick (captioned: time and phase, the
target ringed, the outcome) and, with the ``video`` extra installed, its MP4.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def picker_strip(env: Any, policy: Any, seed: int, frames: int = 6, title: str = "",
                 video: str | Path | None = None, columns: int = 3) -> tuple[np.ndarray, dict[str, Any]]:
    """Run one episode (``render_mode="rgb_array"``) and return ``frames`` evenly spaced frames in
    rows of ``columns`` under ``title``, and the final ``info``. Each frame is captioned with the
    simulated time and the phase (the policy's ``phase`` attribute where it has one, as the
    scripted pickers do, else what ``info`` shows), the target is ringed, and the last frame
    states the outcome and its cause (:mod:`sms3d_env.episode_video`). ``video``: also write the
    whole episode there as MP4 (needs the ``video`` extra)."""
    from generator.image_text import with_title
    from sms3d_env.episode_video import EpisodeVideo

    obs, info = env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset()
    with EpisodeVideo(env, video) as recorder:
        images = [recorder.capture(info, getattr(policy, "phase", None))]
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs))
            done = terminated or truncated
            images.append(recorder.capture(info, getattr(policy, "phase", None), ended=done))
    chosen = [images[i] for i in np.linspace(0, len(images) - 1, frames).round().astype(int)]
    blank = np.full_like(chosen[0], 255)
    chosen += [blank] * (-len(chosen) % columns)
    rows = [np.concatenate(chosen[k:k + columns], axis=1) for k in range(0, len(chosen), columns)]
    grid = np.concatenate(rows, axis=0)
    return (with_title(grid, title) if title else grid), info


#: What the demo picks with: a label, the env's pose-source arguments, and the strip's file name.
PICKS = (
    ("exact poses", {"pose_source": "noisy", "pose_error_deg": 0.0}, "pick_error_0deg.png"),
    ("10° pose error", {"pose_source": "noisy", "pose_error_deg": 10.0}, "pick_error_10deg.png"),
    ("poses from pixels", {"pose_source": "perception"}, "pick_perception.png"),
)


def perception_picture(config: Any, seed: int, path: Path) -> int:
    """Render the bed from the overhead camera, run the shipped two-stage pipeline (RGB-D
    segmenter, then the axis CNN) and save the masks and estimated stem axes beside every
    mushroom's true axis, under a title and a legend; returns the number of mushrooms
    estimated."""
    from generator import generate_scene
    from generator.dataset.render import SceneRenderer
    from perception.pipeline import PosePipeline
    from perception.plots.masks_and_axes import draw_masks_and_axes, save_masks_and_axes_figure

    scene = generate_scene(config, seed)
    cam = scene.config.camera
    with SceneRenderer(cam.height, cam.width) as renderer:
        frame = renderer.render(scene, amodal=False)
    estimates = PosePipeline.shipped()(frame.rgb, frame.depth, frame.intrinsics, frame.world_from_camera)
    rotation, origin = frame.world_from_camera[:3, :3], frame.world_from_camera[:3, 3]
    truth = [((inst.cap_top - origin) @ rotation, inst.stem_axis @ rotation) for inst in scene.instances]
    image = draw_masks_and_axes(frame.rgb, estimates, frame.intrinsics.matrix, truth=truth)
    save_masks_and_axes_figure(
        image, path, f"Shipped perception on the overhead RGB-D image: {len(estimates)} of "
                     f"{len(scene.instances)} mushrooms found (bed seed {seed})",
        estimate_label="estimated stem axis (axis CNN)", truth_label="true stem axis (the scene)",
        mask_label="segmenter mask")
    return len(estimates)


def check_demo_args(out: str | Path, seed: Any, episodes: Any) -> Path:
    """``out`` as a folder path; :class:`~generator.errors.ConfigError` naming ``seed`` or
    ``episodes`` unless they are integers >= 0 and >= 1, ``RunFolderError`` for an empty ``out``
    or a file (before a minute of work, not after it)."""
    from generator.errors import ConfigError
    from generator.run_folder import check_out_path

    for name, value, least in (("seed", seed, 0), ("episodes", episodes, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ConfigError(name, f"must be an integer >= {least}, got {value!r}")
    return check_out_path(out)


def run_demo(out: str | Path = "sms3d_demo", seed: int = 0, episodes: int = 5) -> dict[str, float]:
    """Write ``scene.png``, ``perception.png`` (stage 1 masks, stage 2 axes and the true axes) and
    a picker strip per entry of ``PICKS`` into ``out``, with its MP4 beside it when imageio-ffmpeg
    (the ``video`` extra) is installed; return the success rate of each entry, by label
    (:func:`check_demo_args` checks the arguments first)."""
    import importlib.util

    import gymnasium as gym
    from tqdm.auto import tqdm

    import sms3d_env  # noqa: F401 - registers the environments
    from generator import generate_scene
    from generator.files import save_rgb_png
    from generator.preview import save_preview
    from sms3d_env.pickers.episode import run_episode
    from sms3d_env.pickers.scripted import ScriptedPicker

    out = check_demo_args(out, seed, episodes)
    out.mkdir(parents=True, exist_ok=True)
    from sms3d_env.scene_source import default_scene_config

    config = default_scene_config(touching=True)  # v2's bed: 25 mushrooms whose collision hulls do not overlap
    save_preview(generate_scene(config, seed), out / "scene.png")
    print(f"bed of 25 mushrooms rendered: {out / 'scene.png'}")
    found = perception_picture(config, seed, out / "perception.png")
    print(f"from pixels (shipped segmenter + axis CNN): {found} mushrooms estimated: {out / 'perception.png'}")
    videos = importlib.util.find_spec("imageio_ffmpeg") is not None
    if not videos:
        print('no videos: they need imageio-ffmpeg (pip install "sms3d-pick[video]")')
    rates = {}
    for label, source, name in PICKS:
        env = gym.make("SMS3DPick-v2", scene=config, render_mode="rgb_array", render_camera={"size": (240, 320)},
                       **source)
        picker = ScriptedPicker.for_env(env)
        video = out / Path(name).with_suffix(".mp4") if videos else None
        strip, info = picker_strip(env, picker, seed, video=video,
                                   title=f"Scripted picker, SMS3DPick-v2 gantry, {label}, seed {seed}")
        save_rgb_png(out / name, strip)
        results = [run_episode(env, picker, seed + k) for k in tqdm(range(episodes), desc=f"picking, {label}")]
        env.close()
        reachable = [r for r in results if r["reachable"]]
        rates[label] = float(np.mean([r["success"] for r in reachable])) if reachable else float("nan")
        causes = sorted({r["failure_cause"] for r in reachable if not r["success"]})
        print(f"{label:>18}: {sum(r['success'] for r in reachable)}/{len(reachable)} reachable targets picked"
              f"{'; failures: ' + ', '.join(causes) if causes else ''}; strip: {out / name}"
              f"{f', video: {video}' if video else ''}")
    return rates


def register(subparsers: Any) -> None:
    """Add ``sms3d demo``."""
    summary = ("generate and render a bed, estimate poses from its pixels, then pick with exact, 10°-wrong and "
               "estimated poses")
    p = subparsers.add_parser("demo", help=summary,
                              description=f"{summary[0].upper()}{summary[1:]}: pictures of the bed, of the masks and "
                                          "estimated axes, and of each pick, in --out (an MP4 per pick with the video "
                                          "extra); the picks per pose source are printed. About a minute on two cores.")
    p.add_argument("--out", default="sms3d_demo", help="folder for the pictures (default sms3d_demo, which the repository's .gitignore covers)")
    p.add_argument("--seed", type=int, default=0, help="the bed's and first episode's seed (>= 0)")
    p.add_argument("--episodes", type=int, default=5, help="episodes per pose error (>= 1)")
    p.set_defaults(func=_cmd)


def _cmd(args: Any) -> int:
    import sys

    from generator.errors import ConfigError
    from generator.run_folder import RunFolderError

    try:
        check_demo_args(args.out, args.seed, args.episodes)
    except ConfigError as exc:
        print(f"sms3d demo: error: argument --{exc.field}: {exc.message}", file=sys.stderr)
        return 2
    except RunFolderError as exc:
        print(f"sms3d demo: error: {exc}", file=sys.stderr)
        return 2
    run_demo(args.out, args.seed, args.episodes)
    return 0
