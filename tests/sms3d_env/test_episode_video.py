"""Episode videos and the pick camera: ``eval-policy --video`` writes playable MP4s with the
outcome stamped; the pick camera keeps the target and the tool in view with either robot; the
target's ring sits on the target's cap."""

import json
import os
import subprocess
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import sms3d_env  # noqa: F401 - registers the environments
from generator import SceneConfig
from generator.errors import ConfigError
from sms3d_env.cli import main
from sms3d_env.episode_video import (
    FAILURE_RGB,
    OUTCOME_HOLD_S,
    SUCCESS_RGB,
    EpisodeVideo,
    target_ring,
)
from sms3d_env.pickers.scripted import ScriptedPicker


def _read_mp4(path):
    """(metadata, frames (N, H, W, 3) uint8) of an MP4, decoded by ffmpeg."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    width, height = meta["size"]
    return meta, np.stack([np.frombuffer(f, np.uint8).reshape(height, width, 3) for f in reader])


def test_eval_policy_writes_a_playable_mp4_with_the_outcome_stamped(tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg", reason="the video extra (imageio-ffmpeg) is not installed")
    videos = tmp_path / "videos"
    assert main(["eval-policy", "--episodes", "1", "--num-mushrooms", "8", "--video", str(videos),
                 "--video-size", "120", "160", "--json", str(tmp_path / "eval.json")]) == 0
    res = json.loads((tmp_path / "eval.json").read_text())
    assert res["videos"] == [str(videos / f"episode_{res['seed']}.mp4")]
    assert sorted(p.name for p in videos.iterdir()) == [f"episode_{res['seed']}.mp4"]  # no temporary left
    meta, frames = _read_mp4(res["videos"][0])
    assert meta["codec"] == "h264" and meta["fps"] == 25.0
    # The reset's frame, one per step, then the last held for OUTCOME_HOLD_S.
    assert frames.shape == (1 + res["mean_steps"] + round(OUTCOME_HOLD_S * 25), 120, 160, 3)
    banner = frames[-1, -5:].reshape(-1, 3).mean(axis=0)
    expected = SUCCESS_RGB if res["successes"] else FAILURE_RGB
    assert np.abs(banner - expected).max() < 40, (banner, expected)
    assert np.abs(frames[0, -5:].reshape(-1, 3).mean(axis=0) - expected).max() > 40  # not before the end


@pytest.mark.parametrize("flags, named", [
    (["--video", "{tmp}/clip"], "argument --video: "),
    (["--video", "{tmp}/v", "--video-size", "121", "160"], "argument --video-size: must be two even integers"),
    (["--video", "{tmp}/v", "--video-size", "720", "1280"],
     "argument --video-size: 720 x 1280 is larger than the 480 x 640 that the env's off-screen framebuffer"),
])
def test_eval_policy_refuses_bad_video_flags_before_any_episode(tmp_path, capsys, flags, named):
    (tmp_path / "clip").write_text("")
    assert main(["eval-policy", "--episodes", "1", *(f.format(tmp=tmp_path) for f in flags)]) == 2
    assert named in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip"]  # nothing made


def test_a_folder_of_earlier_videos_is_refused_unless_overwritten_and_orphans_are_removed(tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg", reason="the video extra (imageio-ffmpeg) is not installed")
    videos = tmp_path / "videos"
    videos.mkdir()
    (videos / "episode_7.mp4").write_bytes(b"an earlier run's")
    (videos / "notes.txt").write_text("mine")
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                           check=True)
    orphan = videos / f"episode_9.tmp{ended.stdout.strip()}.mp4"  # what a killed eval left half-written
    orphan.write_bytes(b"cut")
    flags = ["eval-policy", "--episodes", "1", "--num-mushrooms", "8", "--seed", "3", "--video", str(videos),
             "--video-size", "120", "160"]
    assert main(flags) == 2
    assert f"argument --video: {videos} holds 1 episode video(s) of an earlier run" in capsys.readouterr().out
    assert (videos / "episode_7.mp4").read_bytes() == b"an earlier run's"
    assert main([*flags, "--overwrite"]) == 0
    assert sorted(p.name for p in videos.iterdir()) == ["episode_3.mp4", "notes.txt"]


def test_a_frame_larger_than_the_framebuffer_is_refused_at_the_first_capture():
    env = gym.make("SMS3DPick-v1", scene={"placement": {"num_mushrooms": 5}}, render_mode="rgb_array",
                   render_camera={"size": (720, 1280)})
    try:
        _, info = env.reset(seed=0)
        with pytest.raises(ConfigError, match="video_size: 720 x 1280 is larger than the 480 x 640"):
            EpisodeVideo(env).capture(info)
    finally:
        env.close()


def _segmentation(env, camera="pick", size=(120, 160)):
    """Geom id per pixel (-1: none) of ``camera``'s view."""
    u = env.unwrapped
    with mujoco.Renderer(u.model, *size) as renderer:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(u.data, camera=camera)
        ids = renderer.render()
    return np.where(ids[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, ids[..., 0], -1)


@pytest.mark.parametrize("robot", ["gantry", "jaco"])
def test_the_pick_camera_sees_the_target_and_the_cup_as_the_descent_starts(robot):
    # The overhead camera, render()'s old default, looked down through the arm.
    env = gym.make("SMS3DPick-v1", robot=robot, scene=SceneConfig().replace(placement__num_mushrooms=25),
                   render_mode="rgb_array", render_camera={"size": (120, 160)})
    picker = ScriptedPicker.for_env(env)
    obs, info = env.reset(seed=0)
    picker.reset()
    world = env.unwrapped.world
    cap = world.cap_geoms[info["target"]]
    at_reset = (_segmentation(env) == cap).sum()
    assert at_reset > 0.01 * 120 * 160
    while picker.phase != "descend":
        obs, _, terminated, truncated, _ = env.step(picker(obs))
        assert not (terminated or truncated)
    ids = _segmentation(env)
    assert (ids == cap).sum() > 0.9 * at_reset  # the arm does not hide the target
    assert (ids == world.cup_geom).sum() > 10  # and the cup above it is in the picture
    (u, v), radius = target_ring(env.unwrapped, 120, 160)
    window = ids[v - 2:v + 3, u - 2:u + 3]
    assert (window == cap).mean() >= 0.5 and 0 < radius < 60  # the ring sits on the target's cap
    env.close()


def test_image_observations_keep_the_overhead_camera_and_bad_cameras_are_named():
    # The pick camera is aimed with the true pose: image observations must not see through it.
    kw = {"scene": SceneConfig().replace(placement__num_mushrooms=4), "render_mode": "depth_array"}
    default = gym.make("SMS3DPick-v1", image_obs={"size": (48, 64)}, render_camera={"size": (48, 64)}, **kw)
    overhead = gym.make("SMS3DPick-v1", render_camera={"name": "overhead", "size": (48, 64)}, **kw)
    obs, _ = default.reset(seed=0)
    overhead.reset(seed=0)
    assert default.unwrapped.render_camera.name == "pick"
    np.testing.assert_array_equal(obs["depth"][..., 0], overhead.render())
    assert not np.array_equal(default.render(), overhead.render())
    default.close()
    overhead.close()
    with pytest.raises(ValueError, match="RenderCamera.name must be one of .*'pick'.*got 'top'"):
        gym.make("SMS3DPick-v1", render_camera="top")
    with pytest.raises(ValueError, match="ImageObservation.camera must be one of .*'pick'.*got 'top'"):
        gym.make("SMS3DPick-v1", image_obs={"camera": "top"})
