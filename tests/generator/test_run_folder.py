"""The output-folder rule every long-running command follows (generator.run_folder)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from generator.run_folder import (
    LOCK_FILE,
    SETTINGS_FILE,
    RunFolderError,
    differing_settings,
    open_run_folder,
)


def test_a_new_folder_records_its_settings(tmp_path):
    run = open_run_folder(tmp_path / "run", {"lr": 1e-3, "sizes": (1, 2)})
    assert not run.resumed
    assert json.loads((tmp_path / "run" / SETTINGS_FILE).read_text()) == {"lr": 1e-3, "sizes": [1, 2]}


def test_the_same_settings_resume_and_may_change_fields_are_updated(tmp_path):
    open_run_folder(tmp_path, {"lr": 1e-3, "epochs": 2}, may_change=("epochs",))
    (tmp_path / "last.pt").write_bytes(b"x")
    run = open_run_folder(tmp_path, {"lr": 1e-3, "epochs": 5}, may_change=("epochs",))
    assert run.resumed
    assert json.loads((tmp_path / SETTINGS_FILE).read_text())["epochs"] == 5


def test_other_settings_are_refused_naming_each_field_and_nothing_changes(tmp_path):
    open_run_folder(tmp_path, {"lr": 1e-3, "seed": 0, "data": "a"})
    before = (tmp_path / SETTINGS_FILE).read_bytes()
    with pytest.raises(RunFolderError, match=r"data \('a' → 'b'\), lr \(0.001 → 0.01\)") as info:
        open_run_folder(tmp_path, {"lr": 1e-2, "seed": 0, "data": "b"})
    assert "--overwrite" in str(info.value) and str(tmp_path) in str(info.value)
    assert (tmp_path / SETTINGS_FILE).read_bytes() == before


def test_a_growing_field_may_grow_but_not_shrink(tmp_path):
    open_run_folder(tmp_path, {"episodes": 5}, may_grow=("episodes",))
    assert open_run_folder(tmp_path, {"episodes": 8}, may_grow=("episodes",)).resumed
    with pytest.raises(RunFolderError, match=r"episodes \(8 → 3: it may only grow\)"):
        open_run_folder(tmp_path, {"episodes": 3}, may_grow=("episodes",))


def test_overwrite_starts_anew(tmp_path):
    open_run_folder(tmp_path, {"lr": 1e-3})
    (tmp_path / "model.zip").write_bytes(b"old")
    run = open_run_folder(tmp_path, {"lr": 1e-2}, overwrite=True)
    assert not run.resumed and not (tmp_path / "model.zip").exists()


@pytest.mark.parametrize("overwrite", [False, True])
def test_a_folder_of_other_files_is_never_reused_nor_emptied(tmp_path, overwrite):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(RunFolderError, match=SETTINGS_FILE):
        open_run_folder(tmp_path, {"lr": 1e-3}, overwrite=overwrite)
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_an_unreadable_record_is_named(tmp_path):
    (tmp_path / SETTINGS_FILE).write_text("{cut")
    with pytest.raises(RunFolderError, match="unreadable settings record"):
        open_run_folder(tmp_path, {"lr": 1e-3})


@pytest.mark.parametrize("out", ["", "  "])
def test_an_empty_out_is_refused_by_flag(out):
    with pytest.raises(RunFolderError, match="--out must name a folder"):
        open_run_folder(out, {})


def test_a_file_is_no_folder(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(RunFolderError, match="--checkpoint-dir must be a folder"):
        open_run_folder(tmp_path / "f", {}, flag="--checkpoint-dir")


settings = st.dictionaries(st.text(min_size=1, max_size=5),
                           st.one_of(st.integers(), st.floats(allow_nan=False), st.text(max_size=5), st.booleans(),
                                     st.lists(st.integers(), max_size=3)), max_size=5)


@given(settings, settings)
def test_differing_settings_is_empty_exactly_when_the_records_agree(a, b):
    assert (differing_settings(a, b) == []) == (json.loads(json.dumps(a)) == json.loads(json.dumps(b)))
    assert differing_settings(a, b, may_change=set(a) | set(b)) == []


def test_a_second_run_in_a_locked_folder_is_refused_naming_the_folder_and_holder(tmp_path):
    with open_run_folder(tmp_path / "run", {"lr": 1e-3}):
        with pytest.raises(RunFolderError, match=rf"{tmp_path / 'run'}: another run is in progress .*process "
                                                 rf"{os.getpid()}"):
            open_run_folder(tmp_path / "run", {"lr": 1e-3})
    assert open_run_folder(tmp_path / "run", {"lr": 1e-3}).resumed  # released at the block's end


def test_the_lock_of_a_killed_process_is_released_by_the_os(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from generator.run_folder import "
                               "open_run_folder; run = open_run_folder(sys.argv[1], {'lr': 1}); print(flush=True); "
                               "time.sleep(60)", str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        holder.stdout.readline()  # the folder is locked
        with pytest.raises(RunFolderError, match=f"process {holder.pid} holds {LOCK_FILE}"):
            open_run_folder(tmp_path, {"lr": 1})
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert open_run_folder(tmp_path, {"lr": 1}).resumed


def test_overwrite_empties_a_folder_reached_through_a_symbolic_link(tmp_path):
    (tmp_path / "real").mkdir()
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "real", target_is_directory=True)
    open_run_folder(link, {"lr": 1e-3})
    (link / "checkpoints").mkdir()
    (link / "checkpoints" / "ppo_8_steps.zip").write_bytes(b"old")
    run = open_run_folder(link, {"lr": 1e-2}, overwrite=True)
    assert not run.resumed and link.is_symlink()
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == [LOCK_FILE, SETTINGS_FILE]


def test_a_read_only_folder_resumes_without_writing_and_refuses_to_run(tmp_path, read_only_child):
    folder = tmp_path / "run"
    open_run_folder(folder, {"lr": 1e-3}).release()
    (folder / LOCK_FILE).unlink()  # as a folder copied from elsewhere might be
    for p in (tmp_path, folder, *folder.iterdir()):
        p.chmod(0o555 if p.is_dir() else 0o444)
    before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    script = ("import sys; from generator.run_folder import RunFolderError, open_run_folder\n"
              "run = open_run_folder(sys.argv[1], {'lr': 1e-3})\n"
              "print(run.resumed, run.writable)\n"
              "try:\n    run.check_writable()\nexcept RunFolderError as e:\n    print(e)\n")
    done = subprocess.run([sys.executable, "-c", script, str(folder)], capture_output=True, text=True,
                          cwd=Path(__file__).parents[2], check=False, **read_only_child)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == "True False" and "not writable" in done.stdout
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} == before
