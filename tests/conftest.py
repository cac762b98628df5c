import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
# OpenMDAO writes an HTML report folder per problem into the working directory unless told not to
os.environ.setdefault("OPENMDAO_REPORTS", "0")
ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"


def pytest_terminal_summary(terminalreporter: object) -> None:
    """The command-line fuzz's counts per class (tests/test_cli_fuzz.py), in every run's log,
    with or without -s and also from pytest-xdist workers (they travel as user properties)."""
    stats = getattr(terminalreporter, "stats", {})
    for rep in [r for key in ("passed", "failed") for r in stats.get(key, [])]:
        for name, value in getattr(rep, "user_properties", []):
            if name == "cli_fuzz":
                terminalreporter.write_line(f"command-line fuzz ({rep.outcome}): {value}")  # type: ignore[attr-defined]


def pytest_configure(config: object) -> None:
    """With DYNSENS_MODULE_COVERAGE=DIR, record which dynsens modules the run exercises
    (``make test-fast`` checks that the fast subset reaches every one: tests/module_coverage.py)."""
    if os.environ.get("DYNSENS_MODULE_COVERAGE"):
        import module_coverage
        config.pluginmanager.register(module_coverage, "dynsens_module_coverage")  # type: ignore[attr-defined]


SLOW_LIST = Path(__file__).parent / "slow_tests.txt"


def _slow_entries() -> list[str]:
    """Test ids (or their file or class prefixes) listed in tests/slow_tests.txt, comments dropped."""
    lines = (line.split("#", 1)[0].strip() for line in SLOW_LIST.read_text(encoding="utf-8").splitlines())
    return [line for line in lines if line]


@pytest.hookimpl(tryfirst=True)     # before -m and -k deselect
def pytest_collection_modifyitems(config: pytest.Config, items: list) -> None:
    """Mark the tests listed in tests/slow_tests.txt ``slow``: ``make test-fast`` leaves them out,
    ``make test`` runs them.  An entry that matches no test of a collected file is an error (a
    renamed test must not silently rejoin the fast subset, nor a stale entry stay)."""
    entries = _slow_entries()
    used: set[str] = set()
    for item in items:
        nodeid = item.nodeid
        for e in entries:
            if nodeid == e or nodeid.startswith(e + "::") or nodeid.startswith(e + "["):
                item.add_marker(pytest.mark.slow)
                used.add(e)
    files = {item.nodeid.split("::", 1)[0] for item in items}
    whole_files = not any("::" in a for a in config.args)     # not when single tests were asked for
    stale = [e for e in entries if e not in used and e.split("::", 1)[0] in files]
    if stale and whole_files:
        raise pytest.UsageError(f"tests/slow_tests.txt: entries that match no test: {', '.join(stale)}")
