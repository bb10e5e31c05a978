"""``sms3d demo`` on its embedded defaults: every picture it promises, and a pick with poses
estimated from pixels."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import math

import cv2

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
