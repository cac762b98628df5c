"""Fail unless a test run exercised every module of dynsens: the check of ``make test-fast``.

Usage: python scripts/check_module_coverage.py DIR

DIR holds the per-process records that ``tests/module_coverage.py`` writes when pytest runs with
``DYNSENS_MODULE_COVERAGE=DIR``.  A module counts as exercised when one of its functions ran
(in Python, or compiled by numba), or, for a module that defines no function (key tables,
re-exports), when it was imported.  Exit status 1 lists the modules that were not.
"""
from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def defines_functions(path: Path) -> bool:
    """Whether the module has a function or method anywhere in it."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return any(isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) for n in ast.walk(tree))


def unexercised(records: list[dict[str, list[str]]]) -> list[str]:
    """Modules of dynsens/ (paths relative to the repository) that no process exercised."""
    ran = {p for r in records for p in r["ran"] + r["compiled"]}
    imported = {p for r in records for p in r["imported"]}
    missing = []
    for path in sorted((ROOT / "dynsens").rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        if rel in ran or (rel in imported and not defines_functions(path)):
            continue
        missing.append(rel + ("" if rel in imported else " (never imported)"))
    return missing


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    files = sorted(Path(argv[0]).glob("*.json"))
    if not files:
        print(f"no module records in {argv[0]}: run pytest with DYNSENS_MODULE_COVERAGE={argv[0]}",
              file=sys.stderr)
        return 2
    records = [json.loads(f.read_text(encoding="utf-8")) for f in files]
    missing = unexercised(records)
    total = len(list((ROOT / "dynsens").rglob("*.py")))
    if missing:
        print(f"{len(missing)} of {total} dynsens modules not exercised by these tests:", file=sys.stderr)
        for m in missing:
            print(f"  {m}", file=sys.stderr)
        return 1
    print(f"every one of the {total} dynsens modules was exercised ({len(files)} test processes)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
