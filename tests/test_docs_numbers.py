"""The headline numbers a user reads come from one place, benchmarks/headline.json: README.md,
docs/index.md, docs/benchmarks.md and the results page quote them as rendered here, and no stale
count of the per-robot sweep survives beside them."""

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEADLINE = json.loads((ROOT / "benchmarks" / "headline.json").read_text(encoding="utf-8"))
ROBOTS = HEADLINE["scripted_picker_per_robot"]
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


def robot_row(robot):
    """The per-robot table row: successes per error (failure causes when any), cycle time at 0°."""
    n = ROBOTS["episodes"]
    cells = []
    for wins, causes in zip(ROBOTS["successes"][robot], ROBOTS["failures"][robot], strict=True):
        assert sum(causes.values()) == n - wins, f"{robot}: failure causes do not add up to the failures"
        why = ", ".join(f"{cause.replace('_', ' ')} {k}" for cause, k in sorted(causes.items()))
        cells.append(f"{wins}/{n}" if wins == n else f"{wins} ({why})")
    cycle = ROBOTS["cycle_time_s_at_0_deg"][robot]
    return f"| {robot} | " + " | ".join(cells) + f" | {cycle['median']:.2f} / {cycle['p90']:.2f} s |"


def robots_answer():
    """The answer table's sentence on the scripted picker per robot (exact poses, and at 30°)."""
    n, gantry, jaco = ROBOTS["episodes"], ROBOTS["successes"]["gantry"], ROBOTS["successes"]["jaco"]
    at_30 = ROBOTS["errors_deg"].index(30)
    exact = (f"{gantry[0]}/{n} with exact poses on both robots" if gantry[0] == jaco[0]
             else f"{gantry[0]}/{n} (gantry) and {jaco[0]}/{n} (Jaco) with exact poses")
    return f"{exact}, {gantry[at_30]}/{n} (gantry) and {jaco[at_30]}/{n} (Jaco) at a 30° axis error"


def robots_benchmark_cell():
    n, errors = ROBOTS["episodes"], " / ".join(f"{e:g}" for e in ROBOTS["errors_deg"])
    per = {robot: " / ".join(str(k) for k in wins) for robot, wins in ROBOTS["successes"].items()}
    return f"gantry {per['gantry']} and Jaco {per['jaco']} of {n} at {errors}°"


def pixels_answer():
    n, clean, camera = PIXELS["episodes"], PIXELS["successes"]["clean"], PIXELS["successes"]["camera_model"]
    assert len(set(clean.values())) == len(set(camera.values())) == 1, "the sentence quotes one count per robot"
    axis, top = PIXELS["median_axis_error_deg"], PIXELS["median_cap_top_error_mm"]
    return (f"{clean['gantry']}/{n} picked from clean pixels with each robot, as with exact poses (median axis "
            f"error {axis['clean']:.1f}°, cap top {top['clean']:.1f} mm on those targets); {camera['gantry']}/{n} "
            f"with the camera model ({axis['camera_model']:.1f}°, {top['camera_model']:.1f} mm)")


def policy_answer():
    return f"the shipped policy {POLICY['successes']}/{POLICY['episodes']}"


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
    "README.md": [robots_answer, pixels_answer, policy_answer, lambda: robot_row("gantry"), lambda: robot_row("jaco")],
    "docs/index.md": [robots_answer, pixels_answer, policy_answer],
    "docs/benchmarks.md": [robots_benchmark_cell, speed_benchmark_cell, fetch_benchmark_cell],
    "docs/results-environment.md": [lambda: robot_row("gantry"), lambda: robot_row("jaco"), speed_results_row],
}


@pytest.mark.parametrize("name", sorted(QUOTES))
def test_page_quotes_the_headline_numbers(name):
    text = " ".join(_text(name).split())  # a sentence may wrap anywhere
    missing = [quote() for quote in QUOTES[name] if quote() not in text]
    assert missing == [], f"{name} does not quote benchmarks/headline.json; expected, verbatim:\n" + "\n".join(missing)


@pytest.mark.parametrize("name, heading", [
    ("README.md", "SMS3DPick-v1: the scripted picker per robot"),
    ("docs/results-environment.md", "The scripted picker on SMS3DPick-v1, per robot"),
])
def test_per_robot_table_holds_only_the_headline_rows(name, heading):
    rows = [line for line in _section(_text(name), heading).splitlines() if line.startswith(("| gantry |", "| jaco |"))]
    assert rows == [robot_row("gantry"), robot_row("jaco")]


@pytest.mark.parametrize("name", ["README.md", "docs/index.md", "docs/benchmarks.md"])
def test_no_stale_count_of_the_per_robot_sweep(name):
    n = ROBOTS["episodes"]
    measured = {k for wins in ROBOTS["successes"].values() for k in wins}
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
