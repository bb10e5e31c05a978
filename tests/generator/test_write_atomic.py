"""``write_atomic`` leaves the old file or the new one, and never its temporary file."""

import pytest

from generator.files import write_atomic


def test_a_write_that_cannot_be_renamed_into_place_leaves_no_temporary_file(tmp_path):
    # Onto a folder, the rename failed and left out.tmpNNNN beside it.
    (tmp_path / "out").mkdir()
    with pytest.raises(OSError):
        write_atomic(tmp_path / "out", b"png")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
