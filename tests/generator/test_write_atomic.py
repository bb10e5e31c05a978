"""``write_atomic`` leaves the old file or the new one, and never its temporary file."""

import subprocess
import sys

import pytest

from generator.files import remove_orphaned_temporaries, temp_path, write_atomic


def test_a_write_that_cannot_be_renamed_into_place_leaves_no_temporary_file(tmp_path):
    # Onto a folder, the rename failed and left out.tmpNNNN beside it.
    (tmp_path / "out").mkdir()
    with pytest.raises(OSError):
        write_atomic(tmp_path / "out", b"png")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_the_orphaned_temporaries_of_dead_processes_are_removed_and_the_rest_kept(tmp_path):
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                           check=True)
    dead = ended.stdout.strip()
    (tmp_path / f"model.tmp{dead}.zip").write_bytes(b"cut by kill -9")
    (tmp_path / f".recording.tmp{dead}" / "tmpcache").mkdir(parents=True)
    mine = temp_path(tmp_path / "model.zip")
    for kept in (mine, tmp_path / "model.zip", tmp_path / "notes.tmp.txt"):
        kept.write_bytes(b"kept")
    removed = remove_orphaned_temporaries(tmp_path)
    assert sorted(p.name for p in removed) == sorted([f".recording.tmp{dead}", f"model.tmp{dead}.zip"])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["model.zip", "notes.tmp.txt", mine.name])
