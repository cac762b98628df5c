"""Fail if a function of dynsens/ has a cyclomatic complexity above the limit: a check of ``make lint``.

Usage: python scripts/check_complexity.py [--limit N]

Runs radon's complexity visitor (the figures ``radon cc -s dynsens`` prints) over every module of
dynsens/ and lists each function or method above the limit (default 30, issue 32) with its file,
line and complexity; exit status 1 when there is one.  A new kind of response, force or entry
should cost its own function and table entry, not another branch in a long one.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 30


def over_limit(limit: int) -> list[tuple[str, int, str, int]]:
    """(path relative to the repository, line, name, complexity) of each function above ``limit``."""
    try:
        from radon.complexity import cc_visit
    except ImportError:
        raise SystemExit("the complexity check needs radon: pip install 'dynsens[lint]'") from None
    found = []
    for path in sorted((ROOT / "dynsens").rglob("*.py")):
        for block in cc_visit(path.read_text(encoding="utf-8")):
            # classes are reported by radon as the mean of their methods; the methods are listed themselves
            if block.letter in ("F", "M") and block.complexity > limit:
                found.append((str(path.relative_to(ROOT)), block.lineno, block.fullname, block.complexity))
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit", type=int, default=LIMIT, help=f"highest complexity allowed (default {LIMIT})")
    args = parser.parse_args()
    found = over_limit(args.limit)
    for path, line, name, complexity in found:
        print(f"{path}:{line}: {name} has cyclomatic complexity {complexity} (limit {args.limit})")
    if found:
        print(f"{len(found)} function(s) above {args.limit}: split them along their concepts "
              "(a function and a table entry per kind)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
