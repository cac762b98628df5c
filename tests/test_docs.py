"""The documents: every link stays inside the repository and resolves, every anchor names a heading, every
command and Python block runs as printed, every cited test file exists, and the documentation site covers
every page."""
from __future__ import annotations

import doctest
import io
import math
import re
import shlex
from pathlib import Path
from typing import NamedTuple

import click
import pytest
from click.testing import CliRunner

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", REPO / "BENCHMARKS.md", REPO / "CHANGELOG.md", REPO / "CONTRIBUTING.md",
        *sorted((REPO / "docs").glob("*.md"))]
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


def heading_slugs(doc: Path) -> set[str]:
    """The anchors of a document: its headings', as a repository host makes them (code blocks left out), and its
    explicit `<a id="...">` anchors (the generated case reference)."""
    text = re.sub(r"^```.*?^```", "", doc.read_text(encoding="utf-8"), flags=re.M | re.S)
    slugs = {re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-") for title in re.findall(r"^#+ (.+)$", text, re.M)}
    return slugs | set(re.findall(r'<a id="([^"]+)"></a>', text))


@pytest.mark.parametrize("doc", DOCS, ids=[str(d.relative_to(REPO)) for d in DOCS])
def test_anchors_name_a_heading(doc: Path) -> None:
    """`[..](#anchor)` and `[..](page.md#anchor)`: the page has that heading (content moves between pages)."""
    missing = []
    for target in LINK.findall(doc.read_text(encoding="utf-8")):
        path, sep, anchor = target.partition("#")
        if not sep or target.startswith(("http://", "https://")) or path and not path.endswith(".md"):
            continue
        page = (doc.parent / path).resolve() if path else doc
        if page.exists() and anchor not in heading_slugs(page):
            missing.append(target)
    assert not missing, f"{doc.name}: anchors that name no heading: {missing}"


def test_the_anchor_check_can_fail(tmp_path: Path) -> None:
    doc = tmp_path / "x.md"
    doc.write_text("# Title\n\n## Sizing: stress, buckling (`max`)\n\n```\n# not a heading\n```\n<a id=\"k-x\"></a>\n",
                   encoding="utf-8")
    assert heading_slugs(doc) == {"title", "sizing-stress-buckling-max", "k-x"}


def test_readme_is_a_front_page() -> None:
    """The README stays a user's front page (issue 32: under 400 lines); the rest lives in docs/."""
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) < 400, f"README.md has {len(lines)} lines: move sections into docs/"
    text = "\n".join(lines)
    for needed in ("make reproduce-table1", "make test", "## Worked example", "## The Tyrolean weir",
                   "docs/getting-started.md"):
        assert needed in text, needed


def test_every_page_is_in_the_site() -> None:
    """mkdocs.yml's nav names every page of docs/ (a page left out would not be reachable on the site)."""
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8").split("\nnav:", 1)[1]
    named = set(re.findall(r"^\s*- [^#\n]*:\s*([\w\-/]+\.md)\s*$", nav, re.M))      # commented-out entries do not count
    pages = {p.name for p in (REPO / "docs").glob("*.md")}
    top = {"index.md", "changelog.md", "contributing.md", "benchmarks.md"}     # README etc., by the site's hook
    assert pages - named == set(), f"pages missing from mkdocs.yml's nav: {sorted(pages - named)}"
    assert named - pages - top == set(), f"nav entries without a page: {sorted(named - pages - top)}"


def test_commands_table_is_one_table() -> None:
    text = (REPO / "docs" / "commands.md").read_text(encoding="utf-8")
    section = text.split("# Commands", 1)[1].split("\n## ", 1)[0]
    rows = [ln for ln in section.splitlines() if ln.startswith("|")]
    first, last = section.index(rows[0]), section.index(rows[-1])
    assert "\n\n" not in section[first:last], "a blank line breaks the Commands table"
    for command in ("simulate", "check-gradients", "optimize", "convergence"):
        assert any(f"`dynsens {command} " in r for r in rows), command


# --- the command and Python blocks: parsed against the CLI, run, their printed output compared ---
#
# Every fenced block of README.md, CONTRIBUTING.md and docs/*.md that holds a `dynsens ...` command (```console,
# ```bash, ```sh or untagged) is parsed by click against the CLI, with the commands' bodies
# replaced by a no-op: the command and its options exist and their values convert.  A console block
# (`$ dynsens ...` followed by what it prints) is also run, and its output compared.  Every
# ```python block of these documents runs (in a scratch folder that sees the repository's cases/), and
# where it shows output (`>>>` lines), the output is compared.  Numbers are compared within
# NUMBER_RTOL (the documents round); numbers on lines of wall times are not compared.  A block
# too long for the suite is marked by the line `<!-- slow: why -->` right above its fence: it is
# then parsed (commands) or compiled (Python), not run.

NUMBER_RTOL = 1e-4
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
TIMING_LINE = re.compile(r"wall time|Primal-only run")
SLOW = re.compile(r"^<!-- slow(?::\s*(.*?))?\s*-->$")
COMMAND_DOCS = [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted((REPO / "docs").glob("*.md"))]


class Block(NamedTuple):
    doc: Path
    line: int           # 1-based line of the opening fence
    lang: str
    text: str
    slow: str | None    # the reason given by a <!-- slow: ... --> marker, else None

    @property
    def id(self) -> str:
        return f"{self.doc.name}:{self.line}"


def fenced_blocks(doc: Path) -> list[Block]:
    lines = doc.read_text(encoding="utf-8").splitlines()
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        marker = SLOW.match(lines[i - 1].strip()) if i else None
        out.append(Block(doc, i + 1, m.group(1), "\n".join(lines[i + 1:end]),
                         (marker.group(1) or "marked slow") if marker else None))
        i = end + 1
    return out


def command_lines(block: Block) -> list[tuple[list[str], str]]:
    """(argv after `dynsens`, the output printed below it in a console block) of each command."""
    lines = block.text.splitlines()
    console = block.lang == "console" or any(ln.startswith("$ ") for ln in lines)
    out: list[tuple[list[str], str]] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if console and not line.startswith("$ "):
            i += 1
            continue
        line = line[2:] if console else line
        while line.rstrip().endswith("\\") and i + 1 < len(lines):      # continuation lines
            i += 1
            line = line.rstrip()[:-1] + " " + lines[i].strip()
        i += 1
        printed = []
        while console and i < len(lines) and not lines[i].startswith("$ "):
            printed.append(lines[i])
            i += 1
        for words in _split_commands(shlex.split(line, comments=True)):
            while words and re.match(r"^[A-Z_]+=", words[0]):            # VAR=value before a command
                words = words[1:]
            if words[:3] == ["python", "-m", "dynsens"]:
                words = ["dynsens", *words[3:]]
            if words[:1] == ["dynsens"]:
                out.append((words[1:], "\n".join(printed)))
    return out


def _split_commands(words: list[str]) -> list[list[str]]:
    out: list[list[str]] = [[]]
    for w in words:
        if w in ("&&", "||", ";", "|"):
            out.append([])
        else:
            out[-1].append(w)
    return [c for c in out if c]


def _all_blocks(docs: list[Path]) -> list[Block]:
    return [b for d in docs for b in fenced_blocks(d)]


COMMAND_BLOCKS = [b for b in _all_blocks(COMMAND_DOCS) if b.lang in ("console", "bash", "sh", "")
                  and command_lines(b)]
PYTHON_BLOCKS = [b for b in _all_blocks(COMMAND_DOCS) if b.lang == "python"]


def _cli() -> click.Group:
    from dynsens.cli import (check_gradients, convergence, examples, info, modes, optimize, simulate,  # noqa: F401
                             study, verify)
    from dynsens.cli.main import cli
    return cli


@pytest.fixture
def scratch(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder that sees the repository's cases/ (the documents' paths are relative to the
    repository's top directory), with an empty results/."""
    (tmp_path / "cases").symlink_to(REPO / "cases", target_is_directory=True)
    (tmp_path / "results").mkdir()
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_documents_have_command_and_python_blocks() -> None:
    assert len(COMMAND_BLOCKS) >= 7 and len(PYTHON_BLOCKS) >= 4
    assert sum(len(command_lines(b)) for b in COMMAND_BLOCKS) >= 8


def test_slow_markers_stand_right_above_a_fence() -> None:
    for doc in COMMAND_DOCS:
        lines = doc.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            if line.strip().startswith("<!-- slow"):
                assert SLOW.match(line.strip()) and i + 1 < len(lines) and lines[i + 1].startswith("```"), \
                    f"{doc.name}:{i + 1}: a slow marker must be the line right above a block's fence"


@pytest.mark.parametrize("block", COMMAND_BLOCKS, ids=[b.id for b in COMMAND_BLOCKS])
def test_command_blocks_parse_against_the_cli(block: Block, scratch: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cli = _cli()
    for cmd in cli.commands.values():           # parse only: the commands' bodies do nothing
        monkeypatch.setattr(cmd, "callback", lambda *a, **k: None)
    # files the commands read that earlier commands in the documents write
    for name in ("results/weir.h5", "results/weir_opt.h5", "results/tower_opt.h5", "RESULT.h5", "OPT.h5"):
        (scratch / name).touch()
    for argv, _ in command_lines(block):
        res = CliRunner().invoke(cli, argv)
        assert res.exit_code == 0, f"{block.id}: dynsens {shlex.join(argv)}\n{res.output}"


CONSOLE_RUNS = [(b, argv, printed) for b in COMMAND_BLOCKS if not b.slow
                for argv, printed in command_lines(b) if printed.strip()]


@pytest.mark.parametrize("block,argv,printed", CONSOLE_RUNS, ids=[f"{b.id}:{a[0]}" for b, a, _ in CONSOLE_RUNS])
def test_console_blocks_print_what_they_show(block: Block, argv: list[str], printed: str, scratch: Path) -> None:
    res = CliRunner().invoke(_cli(), argv)
    assert res.exit_code == 0, res.output
    assert same_output(printed, res.output), f"{block.id}: dynsens {shlex.join(argv)} now prints\n{res.output}"


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=[b.id for b in PYTHON_BLOCKS])
def test_python_blocks_run_and_print_what_they_show(block: Block, scratch: Path) -> None:
    if ">>>" not in block.text:
        code = compile(block.text, block.id, "exec")
        if not block.slow:
            exec(code, {"__name__": "__readme__"})
        return
    test = doctest.DocTestParser().get_doctest(block.text, {"__name__": "__readme__"}, block.id, str(block.doc),
                                               block.line)
    for example in test.examples:
        compile(example.source, block.id, "single")
    if block.slow:
        return
    exec("import dynsens", test.globs)      # each page imports it in its first block
    report = io.StringIO()
    runner = doctest.DocTestRunner(checker=TolerantChecker(), optionflags=doctest.NORMALIZE_WHITESPACE)
    runner.run(test, out=report.write)
    assert runner.failures == 0, report.getvalue()


class TolerantChecker(doctest.OutputChecker):
    """doctest's comparison, else the same text with every number within NUMBER_RTOL."""

    def check_output(self, want: str, got: str, optionflags: int) -> bool:
        return super().check_output(want, got, optionflags) or same_output(want, got)


def same_output(shown: str, printed: str) -> bool:
    """The same words (whitespace aside) and numbers within NUMBER_RTOL, except on lines of wall times."""
    def parts(text: str) -> tuple[list[str], list[float]]:
        words, numbers = [], []
        for line in text.strip().splitlines():
            timing = bool(TIMING_LINE.search(line))
            words.append(re.sub(r"\s+", "", NUMBER.sub("#", line)))
            numbers += [] if timing else [float(n) for n in NUMBER.findall(line)]
        return [w for w in words if w], numbers
    (w1, n1), (w2, n2) = parts(shown), parts(printed)
    return w1 == w2 and len(n1) == len(n2) and all(math.isclose(a, b, rel_tol=NUMBER_RTOL, abs_tol=1e-12)
                                                   for a, b in zip(n1, n2))


def test_the_output_comparison_can_fail() -> None:
    assert same_output("x = 1.00001  m", "x =   1.000011 m")
    assert not same_output("x = 1.001 m", "x = 1.002 m")
    assert not same_output("x = 1 m", "x = 1 mm")
    assert same_output("wall time 1.2 s", "wall time 9.9 s")


def test_cited_test_files_exist() -> None:
    """Docstrings, scripts and documents cite only test files that exist."""
    cited = set()
    for path in [*(REPO / "dynsens").rglob("*.py"), *(REPO / "scripts").glob("*.py"), *DOCS]:
        cited |= {(path.name, f) for f in re.findall(r"\b(test_\w+\.py)\b", path.read_text(encoding="utf-8"))}
    missing = sorted((where, f) for where, f in cited if not (REPO / "tests" / f).exists())
    assert len(cited) > 20 and not missing, missing


def test_cited_test_functions_exist() -> None:
    """A test cited by name (`test_name` in backquotes, or FILE.py::test_name) is defined in that file, or in tests/."""
    defined: dict[str, set[str]] = {f.name: set(re.findall(r"^\s*def (test_\w+)", f.read_text(encoding="utf-8"), re.M))
                                     for f in (REPO / "tests").glob("test_*.py")}
    every = set().union(*defined.values())
    missing, n = [], 0
    for path in [*(REPO / "dynsens").rglob("*.py"), *(REPO / "scripts").glob("*.py"), *DOCS]:
        text = path.read_text(encoding="utf-8")
        for file, name in re.findall(r"\b(test_\w+\.py)::(test_\w+)", text):
            n += 1
            if name not in defined.get(file, set()):
                missing.append((path.name, f"{file}::{name}"))
        for name in re.findall(r"`(test_\w+)`", text):
            n += 1
            if name not in every:
                missing.append((path.name, name))
    assert n > 10 and not missing, missing


def test_make_targets_in_the_documents_exist() -> None:
    targets = set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(encoding="utf-8"), re.M))
    named = {(d.name, t) for d in COMMAND_DOCS for t in re.findall(r"`make ([\w-]+)`|^make ([\w-]+)",
                                                                   d.read_text(encoding="utf-8"), re.M)}
    missing = sorted((d, t) for d, pair in named for t in pair if t and t not in targets)
    assert len(named) >= 5 and not missing, missing
