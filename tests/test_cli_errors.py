"""Bad command-line input to the scene and dataset commands: exit code 2, a message naming the
flag or field, no traceback, and no file or folder left behind."""

import contextlib
import io

import pytest

from sms3d_env.cli import main


def run_cli(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code
    return code, err.getvalue()


CASES = [
    (["generate", "--num-scenes", "1", "--width", "100000", "--out", "{out}"], "camera.width"),
    (["generate", "--num-scenes", "1000000000", "--out", "{out}"], "num_scenes"),
    (["generate", "--num-scenes", "0", "--out", "{out}"], "num_scenes"),
    (["generate", "--num-scenes", "1", "--seed", "-1", "--out", "{out}"], "seed"),
    (["generate", "--num-scenes", "1", "--out", ""], "--out"),
    (["generate", "--num-scenes", "1", "--config", "{config}", "--out", "{out}"], "terrain.resolution"),
    (["preview", "--width", "0", "--out", "{out}"], "--width"),
    (["preview", "--width", "-5", "--out", "{out}"], "--width"),
    (["preview", "--height", "5000", "--out", "{out}"], "--height"),
    (["preview", "--out", ""], "--out"),
    (["scene", "--seed", "-1", "--out", "{out}"], "seed"),
    (["scene", "--out", ""], "--out"),
    (["scene", "--config", "{ranges}", "--out", "{out}"], "placement.x_range"),
    (["show", "{out}", "--scene", "0", "--out", ""], "--out"),
    (["eval-pipeline", "--data", "{out}", "--edge-tolerance-mm", "-1"], "--edge-tolerance-mm"),
    (["eval-pipeline", "--data", "{out}", "--edge-tolerance-mm", "nan"], "--edge-tolerance-mm"),
    (["train-pose", "--out", "{out}", "--scenes", "{out}", "--edge-tolerance-mm", "8"], "--edge-tolerance-mm"),
    (["train-pose", "--out", "{out}", "--edge-tolerance-mm", "8"], "--edge-tolerance-mm"),
    (["train-pose", "--out", "{out}", "--set", "train.augment.occlusion_prob=1.5"], "train.augment.occlusion_prob"),
    (["train-pose", "--out", "{out}", "--set", "train.augment.occlusion_fraction=[0.6, 0.2]"],
     "train.augment.occlusion_fraction"),
    (["train-pose", "--out", "{out}", "--recipe", "{config}"], "terrain"),
    (["eval-pipeline", "--data", "{out}", "--detector", "oracle", "--edge-tolerance-mm", "8"], "--edge-tolerance-mm"),
    (["show-estimates", "--data", "{out}", "--detector", "oracle", "--soil-margin-mm", "4"], "--soil-margin-mm"),
]


@pytest.mark.parametrize(("argv", "named"), CASES, ids=[" ".join(a) for a, _ in CASES])
def test_bad_input_is_a_usage_error_that_leaves_nothing(tmp_path, monkeypatch, argv, named):
    monkeypatch.chdir(tmp_path)  # "--out ''" would have meant this folder
    config = tmp_path / "config.yaml"
    config.write_text("terrain:\n  resolution: 100000\n")  # would allocate 74 GiB
    ranges = tmp_path / "ranges.yaml"
    ranges.write_text("placement:\n  x_range: [0.1]\n")
    before = sorted(tmp_path.iterdir())
    argv = [a.format(out=tmp_path / "out", config=config, ranges=ranges) for a in argv]
    code, err = run_cli(argv)
    assert code == 2, err
    assert named in err and "Traceback" not in err
    assert sorted(tmp_path.iterdir()) == before


def test_preview_size_check_also_guards_the_library():
    from generator import ConfigError, SceneConfig, generate_scene
    from generator.preview import render_views

    with pytest.raises(ConfigError) as info:
        render_views(generate_scene(SceneConfig().replace(placement__num_mushrooms=1)), width=0)
    assert info.value.field == "width"
