"""Every ```python block of README.md and docs/*.md runs as pasted.

The blocks of one page run in one fresh interpreter (so imports are paid once per page), each
with its own globals and in its own empty working folder: a block that needs an earlier block's
variables or files fails, as it would for a reader who pastes it alone. A block opts out with an
HTML comment on the line before its fence, which the rendered page does not show:

- ``<!-- snippet: slow (why) -->``: runs only with ``pytest -m slow``;
- ``<!-- snippet: skip (the file the reader supplies) -->``: never runs; only for blocks that
  need a file the user supplies.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MARKER = re.compile(r"<!--\s*snippet:\s*(\w+)\s*(.*?)\s*-->")
KINDS = ("slow", "skip")
#: A default-run block must stay quick: the whole suite runs on two cores in a few minutes. Counted
#: in the runner's CPU seconds, not wall seconds, so that a busy machine does not fail a block
#: that costs what it did; a block over this belongs behind a ``slow`` marker.
BLOCK_BUDGET_S = 60.0


@dataclass(frozen=True)
class Block:
    page: str  # path relative to the repository root
    line: int  # line of the opening fence, 1-based
    code: str
    kind: str  # "fast", "slow" or "skip"
    reason: str


def blocks_of(path: Path) -> list[Block]:
    """The ```python blocks of a Markdown file, with the marker of the line before each."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].strip() != "```python":
            i += 1
            continue
        start = i
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == "```"), None)
        if end is None:
            raise ValueError(f"{path}:{start + 1}: a ```python fence is never closed")
        marker = MARKER.fullmatch(lines[start - 1].strip()) if start > 0 else None
        kind, reason = (marker.group(1), marker.group(2)) if marker else ("fast", "")
        if kind not in KINDS + ("fast",) or (marker and not reason):
            raise ValueError(f"{path}:{start}: a snippet marker is 'slow (why)' or 'skip (why)', got {lines[start - 1]!r}")
        blocks.append(Block(str(path.relative_to(ROOT)), start + 1, "\n".join(lines[start + 1:end]) + "\n", kind, reason))
        i = end + 1
    return blocks


ALL_BLOCKS = [block for page in PAGES for block in blocks_of(page)]


def _groups() -> list:
    """One test per page and kind of block that runs: the fast blocks by default, the slow ones
    with ``-m slow``."""
    params = []
    for page in PAGES:
        rel = str(page.relative_to(ROOT))
        for kind in ("fast", "slow"):
            if any(b.page == rel and b.kind == kind for b in ALL_BLOCKS):
                marks = [pytest.mark.slow] if kind == "slow" else []
                params.append(pytest.param(rel, kind, marks=marks, id=f"{rel}-{kind}"))
    return params


@pytest.mark.parametrize(("page", "kind"), _groups())
def test_page_snippets_run_as_pasted(page: str, kind: str, tmp_path: Path) -> None:
    blocks = [b for b in ALL_BLOCKS if b.page == page and b.kind == kind]
    (tmp_path / "blocks.json").write_text(json.dumps([asdict(b) for b in blocks]), encoding="utf-8")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(_runner(tmp_path), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    results_path = tmp_path / "results.json"
    assert results_path.exists(), f"the snippet runner died (exit {proc.returncode}):\n{proc.stderr[-4000:]}"
    results = json.loads(results_path.read_text(encoding="utf-8"))
    failed = [f"{r['where']} failed after {r['seconds']:.1f} s:\n{r['error']}" for r in results if r["error"]]
    assert not failed, "\n\n".join(failed) + f"\n\noutput:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    if kind == "fast":
        slow = [f"{r['where']}: {r['cpu_seconds']:.1f} CPU s" for r in results if r["cpu_seconds"] > BLOCK_BUDGET_S]
        assert not slow, f"blocks over {BLOCK_BUDGET_S:.0f} CPU s; shrink them or mark them slow: {slow}"


def test_snippets_are_found_and_marked_with_reasons() -> None:
    readme = [b for b in ALL_BLOCKS if b.page == "README.md"]
    assert len(readme) >= 3, "the README shows each use with a runnable snippet"
    assert all(b.reason for b in ALL_BLOCKS if b.kind != "fast")


def test_a_marker_without_a_reason_is_refused(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("<!-- snippet: skip -->\n```python\nprint(1)\n```\n", encoding="utf-8")
    with pytest.raises(ValueError, match="snippet marker"):
        blocks_of(page)


def test_a_block_that_uses_an_earlier_blocks_variable_fails(tmp_path: Path) -> None:
    """The runner isolates blocks: what passes here passes for a reader who pastes one block."""
    blocks = [{"page": "p.md", "line": 1, "code": "x = 1\n", "kind": "fast", "reason": ""},
              {"page": "p.md", "line": 5, "code": "print(x)\n", "kind": "fast", "reason": ""}]
    (tmp_path / "blocks.json").write_text(json.dumps(blocks), encoding="utf-8")
    subprocess.run(_runner(tmp_path), cwd=tmp_path, check=True, capture_output=True, timeout=60)
    first, second = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    assert first["error"] == "" and "NameError" in second["error"]


def _runner(folder: Path) -> list[str]:
    """The command that runs ``folder/blocks.json`` into ``folder/results.json``: this file as
    ``__main__`` through ``-c``, so that ``tests/`` (whose ``tests/sms3d_env`` and friends would
    shadow the installed packages) is not put on ``sys.path`` as a script's folder would be."""
    return [sys.executable, "-c", f"import runpy; runpy.run_path({str(Path(__file__))!r}, run_name='__main__')",
            str(folder / "blocks.json"), str(folder / "results.json")]


def _run_blocks(blocks_file: str, results_file: str) -> None:
    """Run each block with fresh globals in a fresh folder under the current one; write one
    result per block (where, wall and CPU seconds, the traceback or "")."""
    base = Path.cwd()
    results = []
    for k, block in enumerate(json.loads(Path(blocks_file).read_text(encoding="utf-8"))):
        where = f"{block['page']}:{block['line']}"
        folder = base / f"block_{k}"
        folder.mkdir()
        os.chdir(folder)
        start, cpu, error = time.perf_counter(), time.process_time(), ""
        try:
            exec(compile(block["code"], where, "exec"), {"__name__": "__main__"})  # noqa: S102 - the docs' own code
        except BaseException:  # a snippet's SystemExit is a failure too
            error = traceback.format_exc()
        results.append({"where": where, "seconds": time.perf_counter() - start,
                        "cpu_seconds": time.process_time() - cpu, "error": error})
        os.chdir(base)
    Path(results_file).write_text(json.dumps(results), encoding="utf-8")


if __name__ == "__main__":
    _run_blocks(sys.argv[1], sys.argv[2])
