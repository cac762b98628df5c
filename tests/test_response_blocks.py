"""Outputs evaluated for blocks of steps give the responses of step-by-step evaluation.

Autonomous batched outputs are evaluated for a whole block of steps (and all gradient
directions) in one call; events, time-point values, KS aggregates and time integrals are
fed block by block.  The reference evaluates every output step by step, as an output that
depends on t explicitly is (``autonomous`` switched off).  Block sizes 1, 7 (boundaries at
steps that do not divide the run, so events fire inside a block and on its first step) and
128.  Tolerance 1e-12 relative (the same arithmetic in another order).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import dynsens
from dynsens.timeloop.march import integrate

CASES = Path(__file__).resolve().parent.parent / "cases"


def _run(case, block: int | None, *, x=None, sensitivities=True, partials=None):
    """block None: the step-by-step reference."""
    plan = replace(case.plan, sensitivities=sensitivities, history=())
    if partials is not None:
        plan = replace(plan, partials=partials)
    rs = case.new_response_set()
    if block is None:
        rs.outputs = [replace(o, autonomous=False) for o in rs.outputs]
        rs.block = 1
    else:
        rs.block = block
    return integrate(case.model, case.x0 if x is None else x, case.scheme, plan, rs,
                     design_names=case.design_names, design_scale=case.scale)


def _assert_same(a, b):
    assert a.status == b.status and a.counters["steps"] == b.counters["steps"]
    assert a.responses.keys() == b.responses.keys()
    for name, ra in a.responses.items():
        rb = b.responses[name]
        assert (ra.missing is None) == (rb.missing is None), name
        if ra.missing:
            continue
        va, vb = np.asarray(ra.value), np.asarray(rb.value)
        scale = max(np.max(np.abs(va)), 1e-300)
        assert np.max(np.abs(va - vb)) <= 1e-12 * scale, name
        if ra.gradient is not None:
            ga, gb = np.asarray(ra.gradient), np.asarray(rb.gradient)
            gscale = max(np.max(np.abs(ga)), 1e-300)
            assert np.max(np.abs(ga - gb)) <= 1e-12 * gscale, name


@pytest.mark.parametrize("name, over", [
    ("hydraulic_lever", []),            # event (interpolated), value at the event and at t = 0, KS
    ("pendulum_3d", []),                # event on a linear output
    ("four_bar", []),                   # time integral of a spring force, KS, end values
    # structural outputs, KS and integral; 0.3 s of the 2 s case: 300 steps still end in a partial
    # block of 7 and of 128 (300 = 42·7 + 6 = 2·128 + 44) and cover the load pulse (0.1 s) and its
    # decay; the check (blocks against step by step, 1e-12) is per step, not of the run's length
    ("duffing_chain", ["integrator.t_end=0.3"]),
    ("slider_crank", ["integrator.t_end=0.3"]),   # time-dependent coefficients: step by step
])
def test_blocks_match_step_by_step(name, over):
    case = dynsens.load_case(CASES / f"{name}.yaml", over)
    ref = _run(case, None)
    for block in (1, 7, 128):
        _assert_same(ref, _run(case, block))


@pytest.mark.parametrize("partials", ["central", "complex"])
def test_blocks_with_an_unperturbed_entry(partials):
    """Central and complex partials add the unperturbed state to each step's block entries."""
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml")
    _assert_same(_run(case, None, partials=partials), _run(case, 7, partials=partials))


def test_blocks_without_sensitivities_and_complex_step():
    """The primal run and a complex-step run of the whole simulation (values complex)."""
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml")
    _assert_same(_run(case, None, sensitivities=False), _run(case, 7, sensitivities=False))
    x = case.x0.astype(complex)
    x[0] += 1e-20j * abs(case.x0[0])
    a, b = _run(case, None, x=x, sensitivities=False), _run(case, 7, x=x, sensitivities=False)
    for name, ra in a.responses.items():
        if ra.missing:
            continue
        im_a, im_b = np.imag(ra.value), np.imag(b.responses[name].value)
        assert np.allclose(im_a, im_b, rtol=1e-12, atol=1e-300), name


def test_event_run_stops_where_it_fires():
    """An event stops the run at the step where it fires, whatever the block size: no step
    beyond it is integrated (the weir's E1/E2 in the shipped case depend on it)."""
    case = dynsens.load_case(CASES / "hydraulic_lever.yaml")
    runs = [_run(case, b) for b in (None, 1, 7, 128)]
    assert runs[0].status == "terminated"
    assert len({r.counters["steps"] for r in runs}) == 1
    assert runs[0].counters["steps"] < case.plan.n_steps
