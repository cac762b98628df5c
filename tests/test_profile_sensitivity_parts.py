"""scripts/profile_sensitivity_parts.py (issue 35's per-step costs of the sensitivity part) runs
from a clone and prints a row per derivative mode whose parts account for no more than the
gradient's extra time they split."""
from __future__ import annotations

import re

import scripts_path  # noqa: F401  (puts scripts/ on the path)
import profile_sensitivity_parts as psp


def test_the_parts_table_of_the_small_chain(capsys):
    psp.main(["--rows", "p1-10", "--repeats", "1"])
    out = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in out.splitlines() if line.startswith("| P1")}
    assert set(rows) == {"P1 N = 10, direct", "P1 N = 10, adjoint"}
    assert "design partials" in rows["P1 N = 10, direct"] and "compiled block" in rows["P1 N = 10, direct"]
    for part in ("design term", "transposed solves", "transposed products", "scheme transposes"):
        assert part in rows["P1 N = 10, adjoint"]
    for line in rows.values():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        assert cells[1] == "2000"                              # steps of P1
        extra = float(cells[3].split()[0])
        parts = [float(v) for v in re.findall(r" (-?\d+\.\d+)(?:;|$)", cells[4])]
        assert parts and all(v >= 0.0 for v in parts)
        assert abs(extra - sum(parts) - float(cells[5])) < 0.2   # the rest is what the parts leave
