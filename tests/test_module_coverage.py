"""The check behind ``make test-fast`` (scripts/check_module_coverage.py): a module counts as
exercised only when one of its functions ran, or, when it defines none, when it was imported."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import check_module_coverage as check  # noqa: E402

ALL = sorted(str(p.relative_to(check.ROOT)) for p in (check.ROOT / "dynsens").rglob("*.py"))
WITH_FUNCTIONS = [m for m in ALL if check.defines_functions(check.ROOT / m)]
WITHOUT_FUNCTIONS = [m for m in ALL if m not in WITH_FUNCTIONS]


def test_every_module_run_passes() -> None:
    assert check.unexercised([{"ran": WITH_FUNCTIONS, "compiled": [], "imported": ALL}]) == []


def test_an_imported_module_whose_functions_never_ran_is_reported() -> None:
    gone = "dynsens/derivatives/gradcheck.py"
    rec = {"ran": [m for m in WITH_FUNCTIONS if m != gone], "compiled": [], "imported": ALL}
    assert check.unexercised([rec]) == [gone]


def test_a_module_never_imported_is_reported_and_compiled_functions_count() -> None:
    assert WITHOUT_FUNCTIONS, "expected modules without functions (e.g. package __init__ files)"
    data_only = WITHOUT_FUNCTIONS[0]
    kernel = "dynsens/models/structural/step_kernels.py"
    rec = {"ran": [m for m in WITH_FUNCTIONS if m != kernel], "compiled": [kernel],
           "imported": [m for m in ALL if m != data_only]}
    assert check.unexercised([rec]) == [f"{data_only} (never imported)"]


def test_the_records_of_several_processes_are_merged(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    half = len(WITH_FUNCTIONS) // 2
    (tmp_path / "gw0.json").write_text(json.dumps({"ran": WITH_FUNCTIONS[:half], "compiled": [], "imported": ALL}))
    (tmp_path / "gw1.json").write_text(json.dumps({"ran": WITH_FUNCTIONS[half:], "compiled": [], "imported": []}))
    assert check.main([str(tmp_path)]) == 0
    (tmp_path / "gw1.json").unlink()
    assert check.main([str(tmp_path)]) == 1
    assert WITH_FUNCTIONS[-1] in capsys.readouterr().err
