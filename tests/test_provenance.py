"""Every result file says what produced it, and ``dynsens info`` prints it (issue 36).

Contract: the root attributes provenance_versions (JSON), provenance_git, provenance_command,
provenance_host, provenance_timezone and case_sha256 (of the effective case, after --set) are in
the files of simulate, optimize and modes; ``dynsens info`` prints them with what the file holds;
a file that is not a dynsens result gets one error, exit status 2.
"""
from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import h5py
from click.testing import CliRunner

import dynsens.cli.info  # noqa: F401  (registers the commands)
import dynsens.cli.modes  # noqa: F401
import dynsens.cli.optimize  # noqa: F401
import dynsens.cli.simulate  # noqa: F401
from dynsens.cli.main import cli

REPO = Path(__file__).resolve().parents[1]
SDOF = REPO / "cases" / "sdof_step.yaml"
TRUSS = REPO / "cases" / "truss_lightweight.yaml"
KEYS = ("provenance_versions", "provenance_git", "provenance_command", "provenance_host", "provenance_timezone",
        "case_sha256")


def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def attrs(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}


def test_a_simulation_file_records_what_produced_it(tmp_path: Path) -> None:
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    assert invoke("simulate", SDOF, "-o", a).exit_code == 0
    assert invoke("simulate", SDOF, "-o", b, "--set", "integrator.dt=0.01").exit_code == 0
    pa, pb = attrs(a), attrs(b)
    for key in KEYS:
        assert key in pa, key
    versions = json.loads(pa["provenance_versions"])
    for name in ("python", "dynsens", "numpy", "scipy", "numba", "h5py", "click", "pyyaml"):
        assert versions[name] and versions[name] != "missing", name
    assert pa["case_sha256"] == hashlib.sha256(pa["case"].encode()).hexdigest()
    assert pa["case_sha256"] != pb["case_sha256"]                  # the effective case, after --set
    assert pa["provenance_host"] and "UTC" in pa["provenance_timezone"]
    if (REPO / ".git").exists():
        head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
        assert pa["provenance_git"].startswith(head.strip())


def test_optimization_and_modes_files_record_it_too(tmp_path: Path) -> None:
    opt, modes = tmp_path / "opt.h5", tmp_path / "modes.h5"
    assert invoke("optimize", TRUSS, "-o", opt, "--no-verify", "--maxiter", "2").exit_code in (0, 1)
    assert invoke("modes", TRUSS, "-o", modes, "--count", "2").exit_code == 0
    for path in (opt, modes):
        pa = attrs(path)
        assert all(k in pa for k in KEYS), path
        assert pa["case_sha256"] == hashlib.sha256(pa["case"].encode()).hexdigest()


def test_info_prints_provenance_and_contents(tmp_path: Path) -> None:
    out = tmp_path / "a.h5"
    assert invoke("simulate", SDOF, "-o", out).exit_code == 0
    r = invoke("info", out)
    assert r.exit_code == 0, r.output
    pa = attrs(out)
    for text in ("simulation file", pa["case_sha256"], "numpy", "host", "responses:", "q_ks"):
        assert text in r.output, text


def test_info_refuses_other_files(tmp_path: Path) -> None:
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = 1
    r = CliRunner().invoke(cli, ["info", str(plain)])
    assert r.exit_code == 2 and "not a dynsens result file" in r.output and "Traceback" not in r.output
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    r = CliRunner().invoke(cli, ["info", str(text)])
    assert r.exit_code == 2 and "not an HDF5 file" in r.output
