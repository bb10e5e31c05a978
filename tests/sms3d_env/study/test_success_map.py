"""The 2-D study: position errors of the noisy source, the success map, the tolerance region,
slices per tool and bed size, and identical rows from the process pool and Ray."""

import json
import math

import numpy as np
import pytest

from generator import SceneConfig, generate_scene
from sms3d_env.pose_sources import NoisyPose, OraclePose
from sms3d_env.study.plan import SweepConfig, plan_tasks
from sms3d_env.study.report import write_report
from sms3d_env.study.success_map import region_summary, success_grid, tolerance_region
from sms3d_env.study.sweep import run_sweep


def _cell_rows(success_by_cell, n=20, tool="suction", size=25):
    """Rows whose success per (error, position) cell is given as a count out of ``n``."""
    rows = []
    for (error, position), wins in success_by_cell.items():
        for k in range(n):
            rows.append({"variant": "default", "source": "noisy", "error_deg": error, "position_error_mm": position,
                         "tool": tool, "num_mushrooms": size, "reachable": True, "success": k < wins,
                         "failure_cause": None if k < wins else "no_seal", "tilt_deg": 10.0 * (k % 5),
                         "nn_distance": 0.01 * (k + 1), "seed": k, "axis_error_deg": error,
                         "cap_top_error_mm": position})
    return rows


GRID = {(0.0, 0.0): 20, (5.0, 0.0): 19, (10.0, 0.0): 17,
        (0.0, 3.0): 20, (5.0, 3.0): 19, (10.0, 3.0): 19,
        (0.0, 6.0): 18, (5.0, 6.0): 15, (10.0, 6.0): 12,
        (0.0, 12.0): 10, (5.0, 12.0): 8, (10.0, 12.0): 5}


def test_tolerance_region_is_the_staircase_within_five_points():
    grid = success_grid(_cell_rows(GRID))
    assert grid["errors_deg"] == [0.0, 5.0, 10.0] and grid["positions_mm"] == [0.0, 3.0, 6.0, 12.0]
    assert grid["success"][0, 0] == 1.0 and grid["n"].min() == 20
    # 10 deg at 0 mm is 15 points down: every row stops at 5 deg; 6 mm is 10 points down even at 0 deg.
    assert tolerance_region(grid) == [(0.0, 5.0), (3.0, 5.0)]
    assert tolerance_region(grid, within_pp=50) == [(0.0, 10.0), (3.0, 10.0), (6.0, 10.0), (12.0, 0.0)]


def test_the_map_report_states_the_region_and_draws(tmp_path):
    rows = _cell_rows(GRID) + _cell_rows({(0.0, 0.0): 18, (5.0, 0.0): 15, (10.0, 0.0): 10}, tool="hand")
    paths = write_report(rows, tmp_path, "sms3d sweep ...")
    assert paths["map"].stat().st_size > 10_000 and paths["slices"].stat().st_size > 10_000
    text = paths["md"].read_text()
    assert "axis error ≤ 5° while the cap-top error is ≤ 3 mm" in text
    assert "| hand | 25 |" in text  # the hand's slice
    md = region_summary(_cell_rows(GRID))
    assert md.count("| default |") == 3  # all, tilted, crowded


def test_slices_over_robots_tools_and_beds_draw_a_panel_per_robot(tmp_path, monkeypatch):
    from sms3d_env.study import figures as study_figures
    from sms3d_env.study import success_map

    figures = []
    for module in (success_map, study_figures):
        monkeypatch.setattr(module, "save_figure", lambda fig, path: figures.append(fig))
    curve = {(0.0, 0.0): 20, (10.0, 0.0): 15}
    rows = [{**r, "robot": robot} for robot in ("gantry", "jaco") for tool in ("suction", "hand")
            for size in (10, 100) for r in _cell_rows(curve, tool=tool, size=size)]
    success_map.plot_slices(rows, tmp_path / "slices.png")
    (fig,) = figures
    assert [ax.get_title() for ax in fig.axes] == ["gantry", "jaco"]
    for ax in fig.axes:  # a line per (tool, bed size), labelled with both
        labels = ax.get_legend_handles_labels()[1]
        assert sorted(label.split(" (n")[0] for label in labels) == [
            "hand, 10 mushrooms", "hand, 100 mushrooms", "suction, 10 mushrooms", "suction, 100 mushrooms"]
    # Only the robot varies: one plot, a line per robot.
    figures.clear()
    success_map.plot_slices([r for r in rows if r["tool"] == "suction" and r["num_mushrooms"] == 10],
                            tmp_path / "robots.png")
    (fig,) = figures
    assert len(fig.axes) == 1 and len(fig.axes[0].get_legend_handles_labels()[1]) == 2


def test_position_error_moves_the_cap_top_by_exactly_that_distance_across_the_estimated_axis():
    scene = generate_scene(SceneConfig().replace(placement__num_mushrooms=6), seed=1)
    truth = OraclePose()(scene, 0, np.random.default_rng(0))
    for seed in range(20):
        est = NoisyPose(10.0, position_error=0.006)(scene, 0, np.random.default_rng(seed))
        rotated = NoisyPose(10.0)(scene, 0, np.random.default_rng(seed))
        offset = est.cap_top - truth.cap_top
        assert np.linalg.norm(offset) == pytest.approx(0.006)
        assert abs(offset @ est.stem_axis) < 1e-12
        np.testing.assert_array_equal(est.rotation, rotated.rotation)  # paired: same rotation draw
        along = NoisyPose(10.0, position_error=0.004, along_axis=True)(scene, 0, np.random.default_rng(seed))
        np.testing.assert_allclose(along.cap_top - truth.cap_top, 0.004 * along.stem_axis, atol=1e-12)
    with pytest.raises(ValueError, match="position_error"):
        NoisyPose(0.0, position_error=math.nan)


def test_new_axes_keep_the_historic_part_names():
    config = SweepConfig(errors_deg=(0.0,), episodes=2, chunk=2, position_errors_mm=(0.0, 6.0),
                         tools=("suction", "hand"), num_mushrooms=(25, 10))
    names = {t.name for t in plan_tasks(config)}
    assert "default_e0_s0-1" in names  # what sweeps before these axes wrote
    assert {"default_e0_p6mm_s0-1", "default_e0_hand_n10_s0-1", "default_e0_p6mm_hand_n10_s0-1"} <= names
    assert len(names) == 8


@pytest.mark.parametrize("flag, value", [("--position-errors-mm", "-3"), ("--position-errors-mm", "nan"),
                                         ("--tool", "gripper")])
def test_sweep_refuses_bad_axis_values_by_flag(tmp_path, capsys, flag, value):
    from sms3d_env.cli import main

    with pytest.raises(SystemExit) if flag == "--tool" else _no_raise():
        code = main(["sweep", "--out", str(tmp_path / "s"), flag, value])
        assert code == 2
        assert flag in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


class _no_raise:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@pytest.mark.slow  # starting a Ray cluster takes ~50 s on 2 cores
def test_process_pool_and_ray_give_the_same_rows(tmp_path):
    pytest.importorskip("ray")
    config = SweepConfig(errors_deg=(0.0, 20.0), position_errors_mm=(0.0, 8.0), episodes=1, chunk=1,
                         num_mushrooms=8)
    pool = run_sweep(config, tmp_path / "pool", workers=2, progress=False)
    ray_rows = run_sweep(config, tmp_path / "ray", workers=2, progress=False, backend="ray")
    assert json.dumps(pool, sort_keys=True) == json.dumps(ray_rows, sort_keys=True)
    assert {r["position_error_mm"] for r in pool} == {0.0, 8.0}
    assert {r["cap_top_error_mm"] for r in pool} == {0.0, 8.0}


@pytest.mark.slow  # ~26 s on 2 cores; test_small_sweep_resumes_and_reports covers resuming from lost parts
def test_a_sweep_killed_with_sigkill_resumes_to_the_same_csv(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    args = ["--errors", "0", "20", "--position-errors-mm", "0", "8", "--episodes", "2", "--chunk", "1",
            "--num-mushrooms", "8", "--workers", "1"]
    cmd = [sys.executable, "-m", "sms3d_env.cli", "sweep"]
    whole = tmp_path / "whole"
    subprocess.run(cmd + ["--out", str(whole)] + args, check=True, capture_output=True)
    killed = tmp_path / "killed"
    proc = subprocess.Popen(cmd + ["--out", str(killed)] + args, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 120
    while not list(killed.glob("parts/*.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(killed.glob("parts/*.json")))
    assert 1 <= done < 8 and not (killed / "sweep.csv").exists()
    subprocess.run(cmd + ["--out", str(killed)] + args, check=True, capture_output=True)
    assert (killed / "sweep.csv").read_bytes() == (whole / "sweep.csv").read_bytes()


def test_a_map_of_sensitivity_variants_only_draws_the_first(tmp_path):
    # `sms3d sweep --variants tight_seal weak_root --position-errors-mm ...` ran no "default".
    rows = _cell_rows(GRID)
    for r in rows:
        r["variant"] = "tight_seal"
    paths = write_report(rows, tmp_path)
    assert paths["map"].stat().st_size > 10_000
    assert "| tight_seal | all reachable targets |" in paths["md"].read_text()
