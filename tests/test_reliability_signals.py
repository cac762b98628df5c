"""SIGTERM and Ctrl-C (SIGINT) at any moment: exit 143 / 130, either no file or the previous
complete one, and no temporary file.  Each test runs the console entry point in a subprocess
and signals it by its process id."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SDOF = REPO / "cases" / "sdof_step.yaml"

# the result file's last group is written, then the process waits inside the atomic write
_SLOW_WRITE = """
import sys, time
import dynsens.io.hdf5 as h
orig = h.write_responses
def slow(g, r):
    orig(g, r)
    print("WRITING", flush=True)
    time.sleep(60)
h.write_responses = slow
from dynsens.cli.main import main
sys.argv = ["dynsens"] + sys.argv[1:]
main()
"""


def _default_sigint() -> None:
    # as from a terminal: a test run started as a background job of a non-interactive shell
    # inherits SIGINT ignored, and so would the child (Python then installs no handler for it)
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(args: list[str], code: str = "from dynsens.cli.main import main; main()") -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)


def _wait_for_line(proc: subprocess.Popen, text: str, timeout: float = 120.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if text in line:
            return
        if not line and proc.poll() is not None:
            break
    proc.kill()
    pytest.fail(f"the subprocess never printed {text!r}: {proc.stderr.read()}")


@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_during_the_write_keeps_the_previous_file(tmp_path, sig, status):
    out = tmp_path / "r.h5"
    out.write_bytes(b"previous complete file")
    proc = _start(["simulate", str(SDOF), "-o", str(out), "--overwrite", "--set", "integrator.t_end=0.5"],
                  _SLOW_WRITE)
    _wait_for_line(proc, "WRITING")
    assert any(p.name.startswith(".r.h5.") for p in tmp_path.iterdir())    # the write is under way
    os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, (proc.returncode, err)
    assert "Traceback" not in err and "no partial output" in err, err
    assert out.read_bytes() == b"previous complete file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]


def test_sigterm_during_the_run_leaves_nothing(tmp_path):
    out = tmp_path / "r.h5"
    # ~10^6 steps with sensitivities: still running when the signal comes
    proc = _start(["simulate", str(SDOF), "-o", str(out), "--set", "integrator.dt=1e-5"])
    time.sleep(4.0)
    assert proc.poll() is None, proc.communicate()
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, (proc.returncode, err)
    assert "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []
