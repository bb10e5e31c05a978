"""The headline numbers a user reads come from one place, benchmarks/headline.json: README.md,
docs/index.md, docs/benchmarks.md and the results page quote them as rendered here, and no stale
count of the per-robot sweep survives beside them."""

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEADLINE = json.loads((ROOT / "benchmarks" / "headline.json").read_text(encoding="utf-8"))
ROBOTS = HEADLINE["scripted_picker_per_robot"]  # SMS3DPick-v2
ROBOTS_V1 = HEADLINE["scripted_picker_per_robot_v1"]  # history
TOLERANCE = HEADLINE["tolerance_table"]
PIXELS = HEADLINE["picking_from_pixels"]
POLICY = HEADLINE["shipped_policy"]
SPEED = HEADLINE["env_speed"]


def _text(name):
    return (ROOT / name).read_text(encoding="utf-8")


def _section(text, heading):
    """The lines under ``heading`` (a Markdown heading's text) up to the next heading of its level."""
    match = re.search(rf"^(#+) {re.escape(heading)}\n", text, re.M)
    assert match, f"heading {heading!r} is missing"
    rest = text[match.end():]
    end = re.search(rf"^#{{1,{len(match.group(1))}}} ", rest, re.M)
    return rest[: end.start() if end else len(rest)]


def robot_row(robot, entry=ROBOTS):
    """The per-robot table row: successes per error (failure causes when any), cycle time at 0°."""
    n = entry["episodes"]
    cells = []
    for wins, causes in zip(entry["successes"][robot], entry["failures"][robot], strict=True):
        assert sum(causes.values()) == n - wins, f"{robot}: failure causes do not add up to the failures"
        why = ", ".join(f"{cause.replace('_', ' ')} {k}" for cause, k in sorted(causes.items()))
        cells.append(f"{wins}/{n}" if wins == n else f"{wins} ({why})")
    cycle = entry["cycle_time_s_at_0_deg"][robot]
    return f"| {robot} | " + " | ".join(cells) + f" | {cycle['median']:.2f} / {cycle['p90']:.2f} s |"


def robots_answer():
    """The answer table's sentence on the scripted picker per robot (exact poses, harvest-ready targets)."""
    n, gantry, jaco = ROBOTS["episodes"], ROBOTS["successes"]["gantry"], ROBOTS["successes"]["jaco"]
    exact = (f"{gantry[0]}/{n} on both robots" if gantry[0] == jaco[0]
             else f"{gantry[0]}/{n} (gantry) and {jaco[0]}/{n} (Jaco)")
    return f"{exact} with exact poses on harvest-ready targets"


def tolerance_answer():
    """The answer table's sentence on the tolerance table: the 25 mm cup per lip compliance."""
    cup = TOLERANCE["tolerated_deg"]["25"][TOLERANCE["default_twist_torque"]]
    s = " / ".join(f"{v:g}" for v in TOLERANCE["lip_compliance_mm"])
    return f"a 25 mm cup whose lip absorbs S = {s} mm tolerates **{' / '.join(f'{v:g}' for v in cup)}°** of stem-axis error"


def tolerance_rows():
    """The study's tolerance table, its first six columns per cup, torque and lip compliance."""
    import math

    rows = []
    for cup, per_torque in TOLERANCE["tolerated_deg"].items():
        for torque, tolerated in per_torque.items():
            for s, deg in zip(TOLERANCE["lip_compliance_mm"], tolerated, strict=True):
                limit = math.degrees(math.atan(s / float(cup)))
                rows.append(f"| {TOLERANCE['robot']} | {s:g} | {cup} | {torque} | {limit:.1f} | "
                            f"{'< 0' if deg is None else f'{deg:g}'} |")
    return rows


def robots_benchmark_cell(entry=ROBOTS):
    n, errors = entry["episodes"], " / ".join(f"{e:g}" for e in entry["errors_deg"])
    per = {robot: " / ".join(str(k) for k in wins) for robot, wins in entry["successes"].items()}
    return f"gantry {per['gantry']} and Jaco {per['jaco']} of {n} at {errors}°"


def pixels_answer():
    n, wins = PIXELS["episodes"], PIXELS["successes"]
    axis, top = PIXELS["median_axis_error_deg"], PIXELS["median_cap_top_error_mm"]
    return (f"from clean pixels {wins['clean']['gantry']}/{n} (gantry) and {wins['clean']['jaco']}/{n} (Jaco), with the "
            f"camera model {wins['camera_model']['gantry']}/{n} and {wins['camera_model']['jaco']}/{n}, against "
            f"{wins['exact']['gantry']}/{n} and {wins['exact']['jaco']}/{n} with exact poses on the same episodes (median "
            f"axis error {axis['clean']:.1f}° / {axis['camera_model']:.1f}°, cap top {top['clean']:.1f} / "
            f"{top['camera_model']:.1f} mm on those targets)")


def policy_answer():
    n, at_10 = POLICY["episodes"], POLICY["at_10_deg"]
    return (f"the shipped policy {POLICY['successes']}/{n} with exact poses and {at_10['successes']}/{n} at a 10° "
            f"axis error (the scripted picker {POLICY['scripted_successes']}/{n} and {at_10['scripted_successes']}/{n})")


def speed_benchmark_cell():
    pool, fresh, times = SPEED["pool_8_steps_per_s"], SPEED["new_bed_per_reset_steps_per_s"], SPEED["pool_times_fetch"]
    return (f"SMS3DPick-v1 {pool[0]:,} / {pool[1]:,} steps/s with an 8-bed pool ({times[0]:.2f} / {times[1]:.2f}× "
            f"Fetch), {fresh[0]:,} / {fresh[1]:,} with a new bed per reset")


def fetch_benchmark_cell():
    rates = [rate for run in SPEED["fetch_steps_per_s_before_after"] for rate in run]
    return f"FetchPickAndPlace-v4 {min(rates):,}–{max(rates):,} steps/s beside them"


def speed_results_row():
    pool, fresh, times = SPEED["pool_8_steps_per_s"], SPEED["new_bed_per_reset_steps_per_s"], SPEED["pool_times_fetch"]
    return (f"| SMS3DPick-v1 (gantry, 10 × 4 ms) | {fresh[0]} / {fresh[1]} | **{pool[0]:,} / {pool[1]:,}** | "
            f"**{times[0]:.2f} / {times[1]:.2f}** |")


QUOTES = {
    "README.md": [tolerance_answer, robots_answer, pixels_answer, policy_answer, lambda: robot_row("gantry"),
                  lambda: robot_row("jaco")],
    "docs/index.md": [tolerance_answer, robots_answer, pixels_answer, policy_answer],
    "docs/benchmarks.md": [robots_benchmark_cell, lambda: robots_benchmark_cell(ROBOTS_V1), speed_benchmark_cell,
                           fetch_benchmark_cell],
    "docs/study.md": [lambda row=row: row for row in tolerance_rows()],
    "docs/results-environment.md": [lambda: robot_row("gantry"), lambda: robot_row("jaco"),
                                    lambda: robot_row("gantry", ROBOTS_V1), lambda: robot_row("jaco", ROBOTS_V1),
                                    speed_results_row],
}


@pytest.mark.parametrize("name", sorted(QUOTES))
def test_page_quotes_the_headline_numbers(name):
    text = " ".join(_text(name).split())  # a sentence may wrap anywhere
    missing = [quote() for quote in QUOTES[name] if quote() not in text]
    assert missing == [], f"{name} does not quote benchmarks/headline.json; expected, verbatim:\n" + "\n".join(missing)


@pytest.mark.parametrize("name, heading, entry", [
    ("README.md", "SMS3DPick-v2: the scripted picker per robot", ROBOTS),
    ("docs/results-environment.md", "The scripted picker on SMS3DPick-v2, per robot", ROBOTS),
    ("docs/results-environment.md", "The scripted picker on SMS3DPick-v1, per robot", ROBOTS_V1),
])
def test_per_robot_table_holds_only_the_headline_rows(name, heading, entry):
    rows = [line for line in _section(_text(name), heading).splitlines() if line.startswith(("| gantry |", "| jaco |"))]
    assert rows == [robot_row("gantry", entry), robot_row("jaco", entry)]


@pytest.mark.parametrize("name", ["README.md", "docs/index.md", "docs/benchmarks.md"])
def test_no_stale_count_of_the_per_robot_sweep(name):
    n = ROBOTS["episodes"]
    assert ROBOTS_V1["episodes"] == n, "the sweep counts of both versions are x/400"
    measured = {k for entry in (ROBOTS, ROBOTS_V1) for wins in entry["successes"].values() for k in wins}
    text = _text(name)
    quoted = [int(k) for k in re.findall(rf"\b(\d+)/{n}\b", text)]
    quoted += [int(k) for run in re.findall(rf"\b((?:\d+ / )+\d+) of {n}\b", text) for k in run.split(" / ")]
    assert quoted and set(quoted) <= measured, f"{name} quotes x/{n} counts {sorted(set(quoted) - measured)} " \
                                               f"that benchmarks/headline.json does not hold"


def test_claims_about_the_robots_follow_from_the_counts():
    gantry, jaco = ROBOTS["successes"]["gantry"], ROBOTS["successes"]["jaco"]
    if not all(g >= j for g, j in zip(gantry, jaco, strict=True)):
        for name in QUOTES:
            assert "as well or better at every error" not in " ".join(_text(name).split()), name


def test_times_fetch_is_the_pool_rate_over_fetch_measured_beside_it():
    for pool, fetch, times in zip(SPEED["pool_8_steps_per_s"], SPEED["fetch_steps_per_s_before_after"],
                                  SPEED["pool_times_fetch"], strict=True):
        assert pool / (sum(fetch) / len(fetch)) == pytest.approx(times, abs=0.005)


def test_every_headline_names_its_command_and_an_existing_results_section():
    for key, entry in HEADLINE.items():
        if key == "about":
            continue
        assert entry["command"].startswith(("python benchmarks/", "sms3d ")), key
        page, anchor = entry["results_page"].split("#")
        headings = re.findall(r"^#+ (.+)$", _text(page), re.M)
        slugs = {re.sub(r"[^\w\- ]", "", h.lower()).strip().replace(" ", "-") for h in headings}
        assert anchor in slugs, f"{key}: {entry['results_page']} has no such section"
