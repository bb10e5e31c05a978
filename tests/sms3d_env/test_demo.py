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
    assert cv2.imread(str(tmp_path / "perception.png")).shape[:2] == (480, 640)
    out = capsys.readouterr().out
    assert "mushrooms estimated" in out and "poses from pixels" in out


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
