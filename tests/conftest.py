import os
import sys
from pathlib import Path

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
