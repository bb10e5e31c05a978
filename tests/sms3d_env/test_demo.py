"""``sms3d demo`` on its embedded defaults: every picture it promises, and a pick with poses
estimated from pixels."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import math
import time

import cv2
import pytest

from sms3d_env.cli import main
from sms3d_env.demo import PICKS, run_demo


def test_the_demo_writes_its_pictures_and_picks_from_pixels(tmp_path, capsys):
    rates = run_demo(tmp_path, seed=0, episodes=1)
    assert set(rates) == {label for label, _, _ in PICKS}
    assert rates["exact poses"] == 1.0  # the scripted picker picks seed 0 with exact poses
    assert not math.isnan(rates["poses from pixels"])
    for name in ("scene.png", "perception.png", *(file for _, _, file in PICKS)):
        image = cv2.imread(str(tmp_path / name))
        assert image is not None and image.size > 0, name
    height, width = cv2.imread(str(tmp_path / "perception.png")).shape[:2]
    assert height > 480 and width > 640  # the 640 x 480 render with its title and legend
    for _, _, name in PICKS:
        # Six 240 x 320 frames in two rows of three under a title bar, and the whole pick as MP4.
        height, width = cv2.imread(str(tmp_path / name)).shape[:2]
        assert width == 3 * 320 and 2 * 240 < height < 2 * 240 + 60, name
        video = cv2.VideoCapture(str(tmp_path / name.replace(".png", ".mp4")))
        ok, frame = video.read()
        assert ok and frame.shape == (240, 320, 3), name
    out = capsys.readouterr().out
    assert "mushrooms estimated" in out and "poses from pixels" in out and "video: " in out


@pytest.mark.parametrize("flags, named", [
    (["--episodes", "0"], "argument --episodes: must be an integer >= 1, got 0"),
    (["--episodes", "-2"], "argument --episodes: must be an integer >= 1, got -2"),
    (["--seed", "-1"], "argument --seed: must be an integer >= 0, got -1"),
    (["--out", ""], "--out must name a folder"),
    (["--out", "file"], "--out must be a folder"),
])
def test_the_demo_refuses_bad_flags_up_front(tmp_path, capsys, monkeypatch, flags, named):
    # --episodes 0 ran the whole demo (88 s) and exited 0.
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file").write_text("")
    start = time.monotonic()
    assert main(["demo", "--out", "demo", *flags]) == 2
    assert time.monotonic() - start < 5
    err = capsys.readouterr().err
    assert err.startswith("sms3d demo: error: ") and named in err, err
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


def test_demo_help_describes_it_and_its_default_folder_is_ignored(capsys):
    import subprocess
    from pathlib import Path

    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    text = capsys.readouterr().out
    assert "pictures of the bed" in text and "--out" in text
    root = Path(__file__).resolve().parents[2]
    assert subprocess.run(["git", "check-ignore", "-q", "sms3d_demo/scene.png"], cwd=root).returncode == 0
