"""Run folders of the behaviour-cloning recipe: inputs are checked before anything is written, and
a folder another run holds is refused naming it."""

from __future__ import annotations

import os

from generator.run_folder import LOCK_FILE, lock_run_folder
from sms3d_env.training import main


def test_nothing_is_written_for_a_bed_size_the_generator_refuses(tmp_path, capsys):
    assert main(["train-policy", "pick_policy", "--out", str(tmp_path / "new"), "--num-mushrooms", "101"]) == 2
    assert "BCConfig.num_mushrooms" in capsys.readouterr().out
    assert not (tmp_path / "new").exists()


def test_a_training_in_a_folder_another_run_holds_is_refused_naming_it(tmp_path, capsys):
    out = tmp_path / "run"
    lock = lock_run_folder(out)  # as a first train-policy running there holds it
    try:
        assert main(["train-policy", "pick_policy", "--out", str(out), "--seed", "64"]) == 2
        assert f"{out}: another run is in progress in this folder (process {os.getpid()}" in capsys.readouterr().out
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
    finally:
        lock.close()
