"""Sources cited by the code are inside the repository (docs/physics.md, docs/anchors.md)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "perception", "sms3d_env", "benchmarks")


def _texts():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*")):
            if path.suffix in (".py", ".md") and path.is_file():
                yield path, path.read_text(encoding="utf-8")


def test_no_citation_points_outside_the_repository():
    offenders = [str(path.relative_to(ROOT)) for path, text in _texts() if "shared/reference" in text]
    assert offenders == []


def test_cited_docs_exist():
    cited = {(path.relative_to(ROOT), m) for path, text in _texts() for m in re.findall(r"docs/[\w-]+\.md", text)}
    assert ("generator/camera.py", "docs/physics.md") in {(str(p), m) for p, m in cited}
    missing = sorted(f"{p}: {m}" for p, m in cited if not (ROOT / m).is_file())
    assert missing == []
