"""The user documents: every link stays inside the repository and resolves, tables are unbroken."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", REPO / "BENCHMARKS.md", REPO / "CHANGELOG.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=[str(d.relative_to(REPO)) for d in DOCS])
def test_links_resolve_inside_the_repository(doc: Path) -> None:
    bad = []
    for target in LINK.findall(doc.read_text(encoding="utf-8")):
        if target.startswith(("http://", "https://", "#")):
            continue
        path = (doc.parent / target.split("#", 1)[0]).resolve()
        if REPO not in path.parents and path != REPO or not path.exists():
            bad.append(target)
    assert not bad, f"{doc.name}: links outside the repository or to missing files: {bad}"


def test_readme_anchors_exist() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    slugs = set()
    for title in re.findall(r"^#+ (.+)$", text, re.M):
        slug = re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")
        slugs.add(slug)
    missing = [a for a in re.findall(r"\]\(#([^)]+)\)", text) if a not in slugs]
    assert not missing, missing


def test_commands_table_is_one_table() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("## Commands", 1)[1].split("\n## ", 1)[0]
    rows = [ln for ln in section.splitlines() if ln.startswith("|")]
    first, last = section.index(rows[0]), section.index(rows[-1])
    assert "\n\n" not in section[first:last], "a blank line breaks the Commands table"
    for command in ("simulate", "check-gradients", "optimize", "convergence"):
        assert any(f"`dynsens {command} " in r for r in rows), command
