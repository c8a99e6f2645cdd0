"""The documentation stays true: every relative link and image resolves, every command is on the front page,
and nothing a user reads points outside the repository."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "companion").rglob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_and_image_resolves(page):
    broken = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"^[a-z]+://", target) or target.startswith(("#", "mailto:")):
            continue
        path = (page.parent / target.split("#", 1)[0]).resolve()
        if not path.exists():
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)}: broken links {broken}"


def test_the_front_page_names_every_command_and_stays_a_front_page():
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.scripts]", 1)[1].split("\n[", 1)[0]       # (no tomllib before Python 3.11)
    scripts = [line.split("=", 1)[0].strip() for line in block.splitlines() if "=" in line]
    assert "flowgap-sitl" in scripts
    readme = (ROOT / "README.md").read_text()
    missing = [name for name in scripts if f"`{name}`" not in readme]
    assert not missing, f"console scripts not in README.md: {missing}"
    assert len(readme.splitlines()) <= 250
    for page in ("design", "vehicle", "companion", "scenes", "perception", "tlog", "training", "evaluation",
                 "benchmarks"):
        assert (ROOT / "docs" / f"{page}.md").is_file() and f"docs/{page}.md" in readme


def test_nothing_a_user_reads_points_outside_the_repository():
    outside = re.compile(r"\.\./shared|DESIGN\.md|/work/")
    files = [*PAGES, *ROOT.glob("companion/**/*.py"), *ROOT.glob("sitl_vehicle/**/*.py"),
             *ROOT.glob("scenes/**/*.py"), *ROOT.glob("tools/**/*.py"), *ROOT.glob("tests/**/*.py")]
    hits = [f"{p.relative_to(ROOT)}:{i + 1}" for p in files if p.name != "test_docs.py"
            for i, line in enumerate(p.read_text().splitlines()) if outside.search(line)]
    assert not hits, hits
