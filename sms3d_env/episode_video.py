"""Episode videos and frames that explain themselves: each frame captioned with the simulated time
and the phase, the target ringed, the outcome and its cause stamped on the frames after the
episode ends. ``EpisodeVideo`` writes them as MP4 (H.264, yuv420p: plays in browsers and common
players) through imageio-ffmpeg, the ``video`` extra (``pip install "sms3d-pick[video]"``).
Rendering is the env's ``rgb_array`` (off-screen: EGL on headless machines).
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from generator.camera import Intrinsics, project, world_from_camera_cv
from generator.config import CameraConfig
from generator.errors import ConfigError
from generator.files import remove_orphaned_temporaries, temp_path
from generator.image_text import put_text

#: Seconds the last frame is repeated at the end of a video, so that the outcome can be read.
OUTCOME_HOLD_S = 1.5
#: Colours (RGB) of the target's ring and of the outcome's banner.
TARGET_RGB = (255, 210, 0)
SUCCESS_RGB = (30, 140, 50)
FAILURE_RGB = (190, 30, 30)
# Lift (m) above which a detached target counts as being lifted, not just detached.
_LIFTING_M = 0.0005
#: The largest frame (height, width) a scene's env renders off-screen with the default scene
#: camera: MuJoCo renders into the model's off-screen framebuffer, which ``generator.mjcf`` sizes
#: to the scene camera's image (``CameraConfig``), and refuses a larger frame mid-episode.
LARGEST_FRAME = (CameraConfig.height, CameraConfig.width)
#: The name of an evaluation's episode video (``eval-policy --video DIR``: ``DIR/episode_<seed>.mp4``).
EPISODE_VIDEO = re.compile(r"episode_\d+\.mp4")


def check_frame_size(size: tuple[int, int], largest: tuple[int, int] = LARGEST_FRAME) -> tuple[int, int]:
    """``size`` (height, width) if a video can have frames of it: even (H.264 halves the colour
    resolution), at least 16 and at most ``largest``, the framebuffer's; ``ConfigError`` naming
    ``video_size`` otherwise, before any episode runs."""
    if not (len(size) == 2 and all(isinstance(n, int) and 16 <= n and n % 2 == 0 for n in size)):
        raise ConfigError("video_size", f"must be two even integers >= 16 (height, width; H.264 halves the "
                                        f"colour resolution), got {tuple(size)!r}")
    if size[0] > largest[0] or size[1] > largest[1]:
        raise ConfigError("video_size", f"{size[0]} x {size[1]} is larger than the {largest[0]} x {largest[1]} "
                                        "that the env's off-screen framebuffer renders (MuJoCo's offheight x "
                                        "offwidth); choose at most that")
    return int(size[0]), int(size[1])


def claim_video_folder(folder: str | Path, overwrite: bool = False) -> Path:
    """``folder`` for a new evaluation's episode videos: ``ConfigError`` naming ``video`` when it
    holds an earlier one's (``EPISODE_VIDEO``), which the new videos would mix with, unless
    ``overwrite``, which deletes those first. Other files in it are left alone."""
    folder = Path(folder)
    earlier = sorted(p for p in folder.iterdir() if EPISODE_VIDEO.fullmatch(p.name)) if folder.is_dir() else []
    if earlier and not overwrite:
        raise ConfigError("video", f"{folder} holds {len(earlier)} episode video(s) of an earlier run "
                                   f"({earlier[0].name}, ...); name an empty folder, or pass --overwrite to "
                                   "replace them")
    for video in earlier:
        video.unlink()
    return folder


def episode_phase(info: dict[str, Any]) -> str:
    """What an ``info`` says the episode is at, whatever the picker: ``approach``, ``holding a
    neighbour``, ``holding the target``, ``detached`` or ``lifting, N mm``."""
    if info["target_detached"] and info["gripped_target"] and info["lift"] > _LIFTING_M:
        return f"lifting, {1000 * info['lift']:.0f} mm"
    if info["target_detached"]:
        return "detached"
    if info["gripped_target"]:
        return "holding the target"
    return "holding a neighbour" if info["gripped"] else "approach"


def outcome_text(info: dict[str, Any]) -> str:
    """``success: picked in T s`` or ``failure: CAUSE`` (one of ``FAILURE_CAUSES``)."""
    if info["is_success"]:
        return f"success: picked in {info['time_s']:.2f} s"
    return f"failure: {info['failure_cause']}"


def target_ring(env: Any, height: int, width: int) -> tuple[tuple[int, int], int] | None:
    """Pixel centre ``(u, v)`` and radius (px) of the target's cap in an ``height`` × ``width``
    render of ``env.render_camera.name`` (the cap's radius at its top's depth, plus a margin); None
    when the cap top is behind the camera."""
    world, target = env.world, env.picking.state.target
    m, d = world.model, world.data
    cam = m.camera(env.render_camera.name).id
    focal = 0.5 * height / np.tan(np.radians(m.cam_fovy[cam]) / 2)
    intrinsics = Intrinsics(width, height, focal, focal, width / 2 - 0.5, height / 2 - 0.5)
    pose = world_from_camera_cv(d.cam_xpos[cam], d.cam_xmat[cam].reshape(3, 3))
    u, v, depth = project(d.site_xpos[world.cap_top_sites[target]][None], pose, intrinsics)[0]
    if depth <= 0:
        return None
    return (int(round(u)), int(round(v))), int(round(1.15 * focal * world.cap_radius[target] / depth)) + 3


def annotate(frame: np.ndarray, caption: str, ring: tuple[tuple[int, int], int] | None,
             outcome: str | None = None, success: bool = False) -> np.ndarray:
    """A copy of ``frame`` (H, W, 3) uint8 RGB with ``caption`` at the top left, the target's
    ``ring`` (centre, radius in px) labelled ``target``, and, once the episode has ended, the
    ``outcome`` on a green (``success``) or red banner across the bottom."""
    out = np.ascontiguousarray(frame).copy()
    h = out.shape[0]
    scale = h / 480  # font scale 1 on a 480-pixel frame; strips of 240-pixel frames stay legible
    line = int(36 * scale)
    put_text(out, caption, (int(8 * scale), line), scale, (255, 255, 255))
    if ring is not None:
        (u, v), radius = ring
        cv2.circle(out, (u, v), radius, TARGET_RGB, max(1, round(2 * scale)), cv2.LINE_AA)
        put_text(out, "target", (u + radius + 3, v - radius // 2), 0.8 * scale, TARGET_RGB)
    if outcome is not None:
        out[h - int(1.4 * line):] = SUCCESS_RGB if success else FAILURE_RGB
        put_text(out, outcome, (int(8 * scale), h - int(0.45 * line)), scale, (255, 255, 255), outline=False)
    return out


def _writer(path: Path, size: tuple[int, int], fps: float) -> Any:
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise ImportError('videos need imageio-ffmpeg: pip install "sms3d-pick[video]"') from exc
    writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         quality=7, macro_block_size=2, ffmpeg_log_level="error")
    writer.send(None)  # start ffmpeg
    return writer


class EpisodeVideo:
    """Annotated frames of one episode of ``env`` (``render_mode="rgb_array"``), streamed to an
    MP4 at ``path`` (or only returned, ``path=None``) at the env's pace (1 / ``control_dt``
    frames per second). The file appears when ``close`` finishes it, complete (written beside
    it first, then renamed; what a killed process left beside it is removed here).
    The first ``capture`` raises ``ConfigError`` naming ``video_size`` when the env renders
    frames larger than its framebuffer (:func:`check_frame_size`).

    Call ``capture(info, phase)`` after ``reset`` and after every ``step``, with ``ended=True``
    after the last, then ``close()``.
    """

    def __init__(self, env: Any, path: str | Path | None = None) -> None:
        self.env = env.unwrapped
        if self.env.render_mode != "rgb_array":
            raise ValueError(f"EpisodeVideo needs an env made with render_mode='rgb_array', got "
                             f"{self.env.render_mode!r}")
        self.path = None if path is None else Path(path)
        self.fps = 1.0 / self.env.control_dt
        self.frames = 0  # captured so far (the file holds them and the held last one)
        self._temp = None if path is None else temp_path(self.path)
        if path is not None:
            remove_orphaned_temporaries(self.path.parent)
        self._writer: Any = None
        self._last: np.ndarray | None = None

    def capture(self, info: dict[str, Any], phase: str | None = None, ended: bool = False) -> np.ndarray:
        """Render, annotate (``phase``: the picker's own, else ``episode_phase(info)``; the
        outcome once ``ended``) and write one frame; returns it, (H, W, 3) uint8."""
        if not self.frames:  # the env's model, and so its framebuffer, exists once it has been reset
            framebuffer = self.env.world.model.vis.global_
            check_frame_size(tuple(self.env.render_camera.size), (framebuffer.offheight, framebuffer.offwidth))
        frame = self.env.render()
        h, w = frame.shape[:2]
        caption = f"t = {info['time_s']:.2f} s | {phase or episode_phase(info)}"
        out = annotate(frame, caption, target_ring(self.env, h, w), outcome_text(info) if ended else None,
                       bool(info["is_success"]))
        if self._temp is not None:
            if self._writer is None:
                self._writer = _writer(self._temp, (w, h), self.fps)
            self._writer.send(out)
        self.frames += 1
        self._last = out
        return out

    def close(self, keep: bool = True) -> None:
        """Hold the last frame ``OUTCOME_HOLD_S`` seconds and finish the file (``keep=False``:
        discard it, as after an error)."""
        if self._writer is None:
            return
        writer, self._writer = self._writer, None
        try:
            if keep:
                for _ in range(round(OUTCOME_HOLD_S * self.fps)):
                    writer.send(self._last)
            writer.close()
            if keep:
                os.replace(self._temp, self.path)
        finally:
            self._temp.unlink(missing_ok=True)

    def __enter__(self) -> EpisodeVideo:
        return self

    def __exit__(self, error: type[BaseException] | None, *_: Any) -> None:
        self.close(keep=error is None)
