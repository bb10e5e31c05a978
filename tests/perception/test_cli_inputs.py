"""The perception commands check what they are given before any long work: a file named by a
flag that is no checkpoint of the kind asked for, a dataset folder that is missing or given
twice — each refused with the flag and the file named, exit 2, nothing evaluated or written."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.cli_detector import check_datasets
from perception.errors import PerceptionConfigError
from sms3d_env.cli import main

#: Ways to name two dataset folders, each with the folder it means.
SPELLINGS = {"a": "a", "a/": "a", "./a": "a", "b/../a": "a", "link_to_a": "a", "b": "b", "b/.": "b", "c": "c"}


@pytest.fixture(scope="module")
def beds(small_dataset):
    """Two 256 x 192 beds of 6 mushrooms, both in the train split."""
    return small_dataset(2, 6, 5, (1.0, 0.0, 0.0))


@pytest.fixture
def garbage(tmp_path):
    path = tmp_path / "garbage.pt"
    path.write_bytes(b"not a checkpoint")
    return path


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Datasets ``a``, ``b`` and ``c`` (manifests of no scenes) and a link to ``a``."""
    root = tmp_path_factory.mktemp("datasets")
    for name in "abc":
        (root / name).mkdir()
        (root / name / "manifest.json").write_text('{"scenes": []}')
    (root / "link_to_a").symlink_to(root / "a")
    return root


@settings(deadline=None)  # the first example imports the dataset readers (torch)
@given(st.lists(st.sampled_from(sorted(SPELLINGS)), min_size=1, max_size=4))
def test_a_dataset_list_is_refused_exactly_when_it_names_a_folder_twice(folders, spellings):
    roots = [f"{folders}/{spelling}" for spelling in spellings]
    meant = [SPELLINGS[spelling] for spelling in spellings]
    if len(set(meant)) == len(meant):
        check_datasets("--data", roots)
    else:
        with pytest.raises(PerceptionConfigError, match="--data: .* is given twice"):
            check_datasets("--data", roots)


@pytest.mark.parametrize("datasets, named", [
    (lambda beds, tmp: [beds, tmp / "missing"], ("missing", "manifest.json")),  # A was evaluated, then the error
    (lambda beds, tmp: [beds, f"{beds}/"], ("given twice",)),  # its scenes counted twice
])
def test_eval_pipeline_checks_every_dataset_before_evaluating_any(beds, tmp_path, capsys, datasets, named):
    out = tmp_path / "report.json"
    assert main(["eval-pipeline", "--data", *map(str, datasets(beds, tmp_path)), "--split", "train",
                 "--detector", "oracle", "--threads", "1", "--out", str(out)]) == 2
    printed = capsys.readouterr()
    assert printed.out == ""  # not even the networks were loaded
    assert "--data" in printed.err and all(n in printed.err for n in named)
    assert not out.exists()


def test_eval_pose_names_a_checkpoint_it_cannot_read(garbage, capsys):
    # It was a traceback from torch.load.
    assert main(["eval-pose", "--checkpoint", str(garbage), "--num", "2"]) == 2
    err = capsys.readouterr().err
    assert "error: --checkpoint" in err and "garbage.pt" in err


def test_train_pose_names_masks_it_cannot_read_before_cutting_any_cloud(beds, garbage, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train-pose", "--out", str(out), "--scenes", str(beds), "--masks", str(garbage), "--epochs", "1",
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "error: --masks" in err and "garbage.pt" in err and not out.exists()
