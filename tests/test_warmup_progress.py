"""The numba warm-up of `make setup` shows its progress (issue 37)."""
from __future__ import annotations

import pytest


def test_the_warm_up_announces_each_case_and_shows_it_is_alive(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 37: `make setup`'s warm-up was silent for minutes; it now names each case before it
    starts and prints the elapsed time while numba compiles."""
    import time
    from dynsens.warmup import heartbeat
    with heartbeat("warming x.yaml (1/2)", every=0.05):
        time.sleep(0.3)
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "warming x.yaml (1/2) ..."
    assert len(out) >= 3 and all("s (compiling" in line for line in out[1:])
