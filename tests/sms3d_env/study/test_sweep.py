import csv
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from generator.dataset.errors import CorruptFileError
from generator.errors import ConfigError
from sms3d_env.cli import main
from sms3d_env.study import report as study_report
from sms3d_env.study.plan import SweepConfig, plan_tasks
from sms3d_env.study.report import summarise, write_report
from sms3d_env.study.statistics import success_table, tolerable_error, wilson_interval
from sms3d_env.study.sweep import run_sweep


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(8, 10)
    assert lo == pytest.approx(0.4902, abs=1e-3) and hi == pytest.approx(0.9433, abs=1e-3)
    assert wilson_interval(0, 20)[0] == 0.0
    assert wilson_interval(20, 20)[1] == pytest.approx(1.0)


def test_wilson_interval_ends_exactly_at_one_and_zero():
    # 57 sample sizes up to 200 gave an upper bound of 0.9999999999999999 for n/n (4/4 first).
    for n in range(1, 501):
        assert wilson_interval(n, n)[1] == 1.0, n
        assert wilson_interval(0, n)[0] == 0.0, n


@given(st.integers(1, 100_000).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))))
def test_wilson_interval_contains_the_estimate(successes_and_n):
    successes, n = successes_and_n
    lo, hi = wilson_interval(successes, n)
    assert 0.0 <= lo <= successes / n <= hi <= 1.0


def _rows(successes_by_error, n=20):
    rows = []
    for error, wins in successes_by_error.items():
        for k in range(n):
            rows.append({"variant": "default", "error_deg": error, "reachable": True, "success": k < wins,
                         "failure_cause": None if k < wins else "no_seal", "tilt_deg": 10.0 * (k % 5),
                         "nn_distance": 0.01 * (k + 1), "seed": k})
    return rows


def test_tolerable_error_is_the_last_error_within_five_points():
    table = success_table(_rows({0.0: 20, 5.0: 19, 10.0: 17, 20.0: 19, 30.0: 5}))
    # 10 deg drops 15 points: the answer stops at 5 deg even though 20 deg recovers.
    assert tolerable_error(table) == 5.0
    assert tolerable_error(success_table(_rows({5.0: 20}))) is None
    causes = {t["error_deg"]: t["causes"] for t in table}
    assert causes[30.0] == {"no_seal": 15}


def test_config_validation():
    with pytest.raises(ValueError, match="errors_deg"):
        SweepConfig(errors_deg=(float("nan"),))
    with pytest.raises(ValueError, match="variants"):
        SweepConfig(variants=("bogus",))
    tasks = plan_tasks(SweepConfig(errors_deg=(0, 5), episodes=5, chunk=2))
    assert len(tasks) == 6 and tasks[0].episode_seeds == (0, 1) and tasks[2].episode_seeds == (4,)


@given(st.sampled_from([("episodes", 1), ("chunk", 1), ("perception_episodes", 0), ("seed", 0)]),
       st.one_of(st.integers(max_value=-1), st.floats(allow_nan=True), st.booleans(), st.text(max_size=3)))
def test_config_refuses_counts_that_are_not_integers_in_range(field_and_least, value):
    name, least = field_and_least
    if isinstance(value, int) and not isinstance(value, bool) and value >= least:
        return  # an integer in range (0 for the counts that may be 0)
    with pytest.raises(ConfigError) as info:
        SweepConfig(**{name: value})
    assert info.value.field == name


@pytest.mark.parametrize("flags", [["--errors", "-5"], ["--errors", "nan"], ["--errors", "0", "181"],
                                   ["--episodes", "0"], ["--chunk", "0"], ["--seed", "-1"],
                                   ["--perception-episodes", "-1"], ["--num-mushrooms", "0"]])
def test_sweep_refuses_bad_flags_by_name_and_creates_nothing(tmp_path, capsys, flags):
    out = tmp_path / "sweep"
    assert main(["sweep", "--out", str(out), "--workers", "1", *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"sms3d sweep: error: argument {flags[0]}: "), err
    assert not out.exists()


def test_a_sweep_that_finished_no_task_does_not_block_the_next_and_a_bad_part_is_named(tmp_path, capsys):
    # A sweep that stopped before any task finished left its settings and no parts.
    (tmp_path / "parts").mkdir()
    (tmp_path / "sweep_config.json").write_text(json.dumps({"seed": 5, "num_mushrooms": 3}))
    args = ["sweep", "--out", str(tmp_path), "--errors", "0", "--episodes", "1", "--num-mushrooms", "8",
            "--workers", "1"]
    assert main(args) == 0
    assert json.loads((tmp_path / "sweep_config.json").read_text())["seed"] == 0
    part = tmp_path / "parts" / "default_e0_n8_s0-0.json"  # 8-mushroom beds: the size is named
    part.write_text(part.read_text()[:40])  # truncated
    with pytest.raises(CorruptFileError, match="default_e0_n8_s0-0.json"):
        run_sweep(SweepConfig(errors_deg=(0.0,), episodes=1, num_mushrooms=8), tmp_path, progress=False)
    capsys.readouterr()
    assert main(args) == 2
    assert str(part) in capsys.readouterr().err


def test_small_sweep_resumes_and_reports(tmp_path):
    config = SweepConfig(errors_deg=(0.0, 30.0), episodes=2, chunk=1, num_mushrooms=8, perception_episodes=1)
    rows = run_sweep(config, tmp_path, progress=False)
    perception = [r for r in rows if r["source"] == "perception"]
    rows = [r for r in rows if r["source"] == "noisy"]
    assert len(rows) == 4 and len(perception) == 1
    assert {r["error_deg"] for r in rows} == {0.0, 30.0}
    # The perception source's stem-axis error is measured, not set: finite and below chance.
    assert 0.0 <= perception[0]["axis_error_deg"] < 90.0
    # Paired design: the same seeds pick the same scenes and targets at every error.
    by_seed = {}
    for r in rows:
        by_seed.setdefault(r["seed"], set()).add(r["target"])
    assert all(len(t) == 1 for t in by_seed.values())
    parts = sorted((tmp_path / "parts").glob("*.json"))
    assert len(parts) == 5
    # A lost part is redone, the others are read back, and the numbers are the same.
    removed = parts[1]
    before = removed.read_text()
    removed.unlink()
    again = run_sweep(config, tmp_path, progress=False)
    assert removed.read_text() == before
    again = [r for r in again if r["source"] == "noisy"]
    assert json.dumps(again, sort_keys=True) == json.dumps(rows, sort_keys=True)
    # Another bed size is another part (bed size is an axis); parts of another detector are not reused.
    nine = {t.name for t in plan_tasks(dataclasses.replace(config, num_mushrooms=9))}
    assert nine.isdisjoint(p.stem for p in parts)
    with pytest.raises(ValueError, match="perception_detector"):
        run_sweep(dataclasses.replace(config, perception_detector="det.pt"), tmp_path, progress=False)
    # Perception parts made with other pose weights are stale.
    record = json.loads((tmp_path / "sweep_config.json").read_text())
    assert len(record["pose_weights_sha256"]) == 16
    (tmp_path / "sweep_config.json").write_text(json.dumps({**record, "pose_weights_sha256": "0" * 16}))
    with pytest.raises(ValueError, match="pose_weights_sha256"):
        run_sweep(config, tmp_path, progress=False)
    # A folder from before bed sizes were named in part files is not resumed at another size.
    (tmp_path / "sweep_config.json").write_text(json.dumps({**record, "num_mushrooms": 10}))
    with pytest.raises(ValueError, match="10-mushroom beds"):
        run_sweep(config, tmp_path, progress=False)
    # Parts copied into another folder without their settings are refused, with the remedy; with
    # the sweep_config.json beside them they are reused.
    copy = tmp_path / "copy"
    (copy / "parts").mkdir(parents=True)
    for part in parts:
        if part.exists() and "perception" not in part.name:
            (copy / "parts" / part.name).write_text(part.read_text())
    with pytest.raises(ValueError, match="holds parts but no sweep_config.json.*copy the sweep_config.json"):
        run_sweep(config, copy, progress=False)
    (copy / "sweep_config.json").write_text(json.dumps(record))
    # Perception settings concern perception parts only: the copied pose-error parts serve a
    # sweep with the camera model too (its perception episodes are run anew).
    realism = dataclasses.replace(config, perception_realism=True)
    copied = [r for r in run_sweep(realism, copy, progress=False) if r["source"] == "noisy"]
    assert json.dumps(copied, sort_keys=True) == json.dumps(rows, sort_keys=True)
    with pytest.raises(ValueError, match="perception_realism"):  # now its perception part is there
        run_sweep(config, copy, progress=False)
    paths = write_report(rows + perception, tmp_path, "sms3d sweep ...")
    with open(paths["csv"]) as fh:
        assert len(list(csv.DictReader(fh))) == 5
    assert paths["png"].stat().st_size > 10_000
    assert "tolerable error" in paths["md"].read_text()
    assert "Perception pose source" in paths["md"].read_text()


def test_robot_is_an_axis_with_a_column_a_curve_and_a_map_per_robot(tmp_path, capsys):
    config = SweepConfig(errors_deg=(0.0, 30.0), position_errors_mm=(0.0, 5.0), episodes=1, num_mushrooms=8,
                         robots=("gantry", "jaco"))
    rows = run_sweep(config, tmp_path, progress=False)
    assert len(rows) == 8 and {r["robot"] for r in rows} == {"gantry", "jaco"}
    # Paired across robots: the same seed draws the same bed and target for both.
    assert len({(r["seed"], r["target"]) for r in rows}) == 1
    paths = write_report(rows, tmp_path, "sms3d sweep --robot gantry jaco")
    with open(paths["csv"]) as fh:
        assert {r["robot"] for r in csv.DictReader(fh)} == {"gantry", "jaco"}
    summary = paths["md"].read_text()
    assert "gantry, suction, 8 mushrooms" in summary and "jaco, suction, 8 mushrooms" in summary
    # The cycle time of the successful picks, per robot (the exact-pose episodes pick).
    assert "## Cycle time" in summary and all(r["time_s"] > 0 for r in rows)
    assert sorted(paths.values()) == sorted(set(paths.values()))  # each file named once
    assert paths["map"].is_file() and (tmp_path / "sweep_map_jaco_suction_n8.png").is_file()
    assert paths["slices"].is_file()
    with pytest.raises(ConfigError) as info:
        SweepConfig(robots=("gantry", "ur5"))
    assert info.value.field == "robots"
    with pytest.raises(SystemExit) as exited:
        main(["sweep", "--out", str(tmp_path / "bad"), "--robot", "ur5"])
    assert exited.value.code == 2 and "--robot: invalid choice: 'ur5'" in capsys.readouterr().err
    # A folder of SMS3DPick-v0 parts (recorded before the env id was) is not resumed by a v2 sweep.
    record = json.loads((tmp_path / "sweep_config.json").read_text())
    assert record["env_id"] == "SMS3DPick-v2"
    del record["env_id"]
    (tmp_path / "sweep_config.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="env_id: folder has 'SMS3DPick-v0'"):
        run_sweep(config, tmp_path, progress=False)


def test_target_rule_is_an_axis_whose_rows_pick_from_their_class(tmp_path, capsys):
    config = SweepConfig(errors_deg=(0.0,), episodes=2, num_mushrooms=25, targets=("harvest_ready", "small"))
    rows = run_sweep(config, tmp_path, progress=False)
    assert sorted(r["target_rule"] for r in rows) == ["harvest_ready"] * 2 + ["small"] * 2
    # Each row's target is of its class: a small cap is below the harvest size, a ready one at it.
    from sms3d_env.targets import HARVEST_DIAMETER

    assert all((r["cap_diameter"] < HARVEST_DIAMETER) == (r["target_rule"] == "small") for r in rows)
    assert {t.name.endswith("_tsmall_s0-1") for t in plan_tasks(config)} == {False, True}
    summary = write_report(rows, tmp_path)["md"].read_text()
    assert "| gantry | suction | 25 | small |" in summary and "| gantry | suction | 25 | harvest-ready |" in summary
    with pytest.raises(ConfigError) as info:
        SweepConfig(targets=("index",))  # names one mushroom of one bed: nothing to sweep
    assert info.value.field == "targets"
    assert main(["sweep", "--out", str(tmp_path / "bad"), "--target", "ripest"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sms3d sweep: error: argument --target: must be distinct target rules") and "'ripest'" in err
    assert not (tmp_path / "bad").exists()


def test_report_draws_when_every_episode_of_an_error_succeeds(tmp_path):
    # `sms3d sweep --errors 0 --episodes 4 --chunk 4`: 4/4 successes drew a negative error bar.
    paths = write_report(_rows({0.0: 4, 5.0: 3}, n=4), tmp_path)
    assert paths["png"].stat().st_size > 10_000
    assert "| 0° | 100.0 % | 51.0–100.0 % | 4 |" in paths["md"].read_text()


def test_a_failed_report_leaves_no_earlier_report_behind(tmp_path, monkeypatch):
    paths = write_report(_rows({0.0: 20}), tmp_path)
    assert all(p.is_file() for p in paths.values())

    def fail(*args, **kwargs):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(study_report, "plot_sweep", fail)
    with pytest.raises(RuntimeError, match="plot failed"):
        write_report(_rows({0.0: 10}), tmp_path)
    assert not any(p.exists() for p in paths.values())
    assert list(tmp_path.iterdir()) == []  # no temporary files either


def test_mcnemar_counts_only_discordant_pairs():
    from sms3d_env.study.statistics import mcnemar_p

    same = [True, False, True]
    assert mcnemar_p(same, same) == 1.0
    # 10 pairs where only the first picker succeeds: p = 2 / 2**10.
    assert mcnemar_p([True] * 10 + [False] * 5, [False] * 10 + [False] * 5) == pytest.approx(2 / 1024)


def test_sweep_compare_keeps_two_sweeps_of_one_picker(tmp_path, capsys):
    """Two sweeps of the scripted picker (here: the default and the tool-following IK posture)
    are two curves, the second named by its folder, not one silently replaced."""
    cfg = SweepConfig(errors_deg=(0.0,), episodes=1, num_mushrooms=8)
    run_sweep(cfg, tmp_path / "default", progress=False)
    tool = {"controller": {"posture_target": "tool"}}
    run_sweep(dataclasses.replace(cfg, env_kwargs=tool), tmp_path / "tool", progress=False)
    assert main(["sweep-compare", str(tmp_path / "default"), str(tmp_path / "tool"),
                 "--out", str(tmp_path / "cmp.png")]) == 0
    table = capsys.readouterr().out
    assert "| scripted picker | 0° |" in table and "| scripted picker (tool) | 0° |" in table
    assert (tmp_path / "cmp.png").stat().st_size > 0


def test_a_sweep_of_an_earlier_version_resumes_with_its_env_options_read_as_now(tmp_path):
    """A folder whose settings name the env options as the constructor took them before its
    arguments were regrouped (``posture_target``) resumes under the same options given now
    (``controller``), without running a part again; other options are still refused."""
    cfg = SweepConfig(errors_deg=(0.0,), episodes=1, num_mushrooms=8,
                      env_kwargs={"controller": {"posture_target": "tool"}})
    rows = run_sweep(cfg, tmp_path, progress=False)
    settings = tmp_path / "sweep_config.json"
    settings.write_text(json.dumps({**json.loads(settings.read_text()), "env_kwargs": {"posture_target": "tool"}}))
    made = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "parts").glob("*.json")}
    assert run_sweep(cfg, tmp_path, progress=False) == rows
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "parts").glob("*.json")} == made
    with pytest.raises(ValueError, match="env_kwargs"):
        run_sweep(dataclasses.replace(cfg, env_kwargs={}), tmp_path, progress=False)


def test_a_killed_sweep_leaves_no_worker(tmp_path, processes):
    """``kill -9`` of a sweep with a process pool ends its workers too: an orphan would keep
    writing parts beside the resumed sweep."""
    cmd = [sys.executable, "-m", "sms3d_env.cli", "sweep", "--out", str(tmp_path / "sweep"), "--errors", "0", "10",
           "--episodes", "40", "--num-mushrooms", "8", "--workers", "2"]
    proc = subprocess.Popen(cmd, env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(workers := processes.pool_workers(proc.pid)) < 2:
        assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before its workers started"
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert processes.survivors(workers) == []


@pytest.mark.slow  # starting a Ray cluster; the process-pool kill test stays in the default suite
def test_a_killed_ray_sweep_leaves_no_ray_process(tmp_path, processes):
    """``kill -9`` of a sweep on Ray ends every process of its cluster at once: the raylet's agents
    used to wait 60-105 s on the dead GCS server, and a running task kept writing parts."""
    pytest.importorskip("ray")
    cmd = [sys.executable, "-m", "sms3d_env.cli", "sweep", "--out", str(tmp_path / "sweep"), "--errors", "0", "10",
           "--episodes", "40", "--num-mushrooms", "8", "--workers", "1", "--backend", "ray"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def tree() -> list[int]:
        found, frontier = [], processes.children(proc.pid)
        while frontier:
            found.append(pid := frontier.pop())
            frontier += processes.children(pid)
        return found

    def running_task(pid: int) -> bool:
        try:
            return open(f"/proc/{pid}/cmdline", "rb").read().startswith(b"ray::_run_and_save")
        except OSError:
            return False

    deadline = time.monotonic() + 120
    while not any(running_task(pid) for pid in tree()):
        assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before its first Ray task"
        time.sleep(0.05)
    ray_processes = tree()
    time.sleep(2.0)  # four of the watchdog's 0.5 s rounds: it has noted every process listed above
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert processes.survivors(ray_processes, wait_s=15.0) == []


def _sweep_folder(folder, picker="scripted", seeds=range(4), errors=(0.0, 10.0), size=25, variant="default"):
    """A sweep folder with one part file of hand-made rows (what ``load_rows`` reads)."""
    (folder / "parts").mkdir(parents=True)
    rows = [{"variant": variant, "picker": picker, "source": "noisy", "error_deg": e, "position_error_mm": 0.0,
             "tool": "suction", "num_mushrooms": size, "seed": s, "reachable": True, "success": (s + int(e)) % 3 > 0,
             "failure_cause": None if (s + int(e)) % 3 else "no_seal"} for e in errors for s in seeds]
    (folder / "parts" / "all.json").write_text(json.dumps(rows))
    return folder


@pytest.mark.parametrize("other, named", [
    ({"size": 8}, "bed size 8 mushrooms"),
    ({"seeds": range(10, 14)}, "seeds 10–13"),
    ({"errors": (0.0, 20.0)}, "errors 0°, 20°"),
    ({"seeds": (0, 1, 2, 5)}, "seeds 0–2, 5"),
])
def test_sweep_compare_refuses_sweeps_that_did_not_run_the_same_episodes(tmp_path, capsys, other, named):
    # Side by side, other beds or seeds gave McNemar p = nan: no episode pairs.
    first = _sweep_folder(tmp_path / "a")
    second = _sweep_folder(tmp_path / "b", picker="policy:x", **other)
    assert main(["sweep-compare", str(first), str(second), "--out", str(tmp_path / "cmp.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sms3d sweep-compare: error: ") and "cannot be paired" in err
    assert str(second) in err and str(first) in err and named in err, err
    assert not (tmp_path / "cmp.png").exists()


def test_sweep_compare_refuses_a_sweep_without_the_default_physics(tmp_path, capsys):
    # It used to be left out of the table and the figure without a word.
    first = _sweep_folder(tmp_path / "a")
    tight = _sweep_folder(tmp_path / "tight", variant="tight_seal")
    assert main(["sweep-compare", str(first), str(tight), "--out", str(tmp_path / "cmp.png")]) == 2
    err = capsys.readouterr().err
    assert f"{tight} holds no episodes of the noisy pose source with the default physics" in err


def test_sweep_compare_names_the_shipped_pickers_as_the_documentation_does(tmp_path, capsys, monkeypatch):
    # A figure's legend once said "residual" where the text named the picker.
    import sms3d_env.study.figures as figures

    legends = []
    monkeypatch.setattr(figures, "save_figure",
                        lambda fig, path: legends.append([t.get_text() for t in fig.axes[0].get_legend().get_texts()]))
    folders = [_sweep_folder(tmp_path / name, picker=name) for name in ("scripted", "policy")]
    assert main(["sweep-compare", *map(str, folders), "--out", str(tmp_path / "cmp.png")]) == 0
    table = capsys.readouterr().out
    names = ("scripted picker", "shipped policy")
    assert [label.split(" (n = ")[0] for label in legends[0]] == list(names)
    assert all(f"| {name} | 10° |" in table for name in names), table


def test_sweep_compare_labels_sweeps_of_one_name_by_their_paths(tmp_path, capsys):
    folders = [_sweep_folder(tmp_path / parent / "run") for parent in ("x", "y", "z")]
    assert main(["sweep-compare", *map(str, folders), "--out", str(tmp_path / "cmp.png")]) == 0
    table = capsys.readouterr().out
    for label in ("scripted picker", "scripted picker (y/run)", "scripted picker (z/run)"):
        assert f"| {label} | 10° | 3/4 = 75.0 % |" in table, table
    assert "nan" not in table
    assert (tmp_path / "cmp.png").stat().st_size > 0


@pytest.mark.parametrize("out", ["", "folder", "missing/cmp.png"])
def test_sweep_compare_refuses_an_output_it_cannot_write_before_reading_sweeps(tmp_path, capsys, out):
    (tmp_path / "folder").mkdir()
    sweep = _sweep_folder(tmp_path / "a")
    target = str(tmp_path / out) if out else out
    assert main(["sweep-compare", str(sweep), "--out", target]) == 2
    assert capsys.readouterr().err.startswith("sms3d sweep-compare: error: --out ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "folder"]  # no temporary file either


def test_sweep_refuses_an_empty_or_file_out(tmp_path, capsys, monkeypatch):
    # An empty --out ran the sweep in the current folder.
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file").write_text("")
    for out in ("", "file"):
        assert main(["sweep", "--out", out, "--errors", "0", "--episodes", "1", "--workers", "1"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("sms3d sweep: error: ") and "--out must" in err, err
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


def test_a_resumed_sweep_refuses_a_learned_picker_whose_config_changed(tmp_path, monkeypatch):
    """The picker's ``config.json`` sets the env it acts in: parts made with another are stale."""
    from sms3d_env.policies.loader import SHIPPED_POLICY
    from sms3d_env.study import resume

    picker = tmp_path / "policy"
    picker.mkdir()
    for name in ("model.zip", "config.json"):
        (picker / name).write_bytes((SHIPPED_POLICY.parent / name).read_bytes())
    config = SweepConfig(errors_deg=(0.0,), episodes=1, num_mushrooms=8, picker=f"policy:{picker / 'model.zip'}")
    out = tmp_path / "sweep"
    (out / "parts").mkdir(parents=True)
    (out / "sweep_config.json").write_text(json.dumps(resume.settings(config)))
    (out / "parts" / f"{plan_tasks(config)[0].name}.json").write_text("[]")  # the sweep's one task, done
    assert run_sweep(config, out, progress=False) == []  # the same files: resumed
    saved = json.loads((picker / "config.json").read_text())
    (picker / "config.json").write_text(json.dumps({**saved, "env_options": {**saved["env_options"],
                                                                             "end_on_dead_end": False}}))
    with pytest.raises(ValueError, match=f"picker files changed since the parts were made: {picker / 'config.json'}"):
        run_sweep(config, out, progress=False)


def test_the_table_counts_failed_attempts_that_knocked_the_target_off():
    rows = _rows({0.0: 18, 30.0: 10})
    for k, r in enumerate(rows):
        # every third episode ends with the target off its root: picked, or knocked off in a failure
        r["target_detached"] = r["success"] or k % 3 == 0
    # Failures are rows 18-19 (0 deg) and 30-39 (30 deg); of those, 18, 30, 33, 36 and 39 are off.
    table = {t["error_deg"]: t["knocked_off"] for t in success_table(rows)}
    assert table == {0.0: 1, 30.0: 4}
    assert "| 30° | 50.0 % | 29.9–70.1 % | 20 | no_seal 10 | 4 |" in summarise(rows)
