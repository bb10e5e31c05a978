"""``sms3d learning-curve`` on runs it must not confuse or lose: runs of one folder name, and an
output it cannot write."""

import pytest

from sms3d_env.cli import main

PROGRESS = "time/total_timesteps,time/time_elapsed,eval/success_rate\n2048,10,\n4096,,{}\n"


def _run(folder, success):
    folder.mkdir(parents=True)
    (folder / "progress.csv").write_text(PROGRESS.format(success))
    return folder


def test_runs_of_one_folder_name_are_labelled_by_their_paths(tmp_path, capsys):
    # Labelled by folder name, the second seed0 replaced the first.
    runs = [_run(tmp_path / "sweep_a" / "seed0", 0.25), _run(tmp_path / "sweep_b" / "seed0", 0.75),
            _run(tmp_path / "sweep_b" / "seed1", 0.5)]
    assert main(["learning-curve", *map(str, runs), "--out", str(tmp_path / "c.png")]) == 0
    out = capsys.readouterr().out
    for label, success in (("sweep_a/seed0", 25), ("sweep_b/seed0", 75), ("seed1", 50)):
        assert f"| {label} | 1 | 4096 | 0.2 | {success} % |" in out, out


def test_a_run_given_twice_is_refused_by_name(tmp_path, capsys):
    run = _run(tmp_path / "seed0", 0.5)
    assert main(["learning-curve", str(run), str(tmp_path / "." / "seed0"), "--out", str(tmp_path / "c.png")]) == 2
    assert "given twice" in capsys.readouterr().err


@pytest.mark.parametrize("out", ["", "folder", "missing/c.png"])
def test_an_output_it_cannot_write_is_refused_and_leaves_nothing(tmp_path, capsys, out):
    # --out naming a folder left lc.tmpNNNN beside it, after the curves were drawn.
    run = _run(tmp_path / "seed0", 0.5)
    (tmp_path / "folder").mkdir()
    assert main(["learning-curve", str(run), "--out", str(tmp_path / out) if out else out]) == 2
    assert capsys.readouterr().err.startswith("sms3d learning-curve: error: --out ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "seed0"]
