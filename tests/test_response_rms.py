"""``type: rms`` (dynsens/responses/types/rms.py, the response type declared in its own module):
the undamped oscillator's closed form, the gradient against complex step of the whole run (also
for a run ended by an event), the adjoint against the direct mode, and input errors."""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from helpers import complex_step_gradients, rel_err

DISP = {"dof": "u", "kind": "displacement"}
VEL = {"dof": "u", "kind": "velocity"}
EVENT = [{"name": "far", "quantity": DISP, "value": 0.3, "direction": "rising"}]


def _case(responses, over=(), events=None, t_end=2.0):
    import yaml
    raw = yaml.safe_load((CASES / "sdof_step.yaml").read_text())
    raw["responses"] = responses
    if events:
        raw["events"] = events
    raw["integrator"]["t_end"] = t_end
    raw["sensitivity"]["partials"] = "complex"
    return dynsens.load_case_dict(raw, source="sdof.yaml", overrides=list(over))


def test_rms_of_the_velocity_over_whole_periods_matches_the_closed_form():
    """Undamped, at rest under a step force F: v = (F/k) ω sin ωt, whose RMS over whole periods is
    (F/k) ω / √2.  Over two periods the Newmark (trapezoidal) scheme's O(Δt²) error: below 1e-5
    relative at Δt = 1 ms, about a quarter of it at 0.5 ms."""
    F, k, m = 10.0, 50.0, 2.0
    w = np.sqrt(k / m)
    exact = F / k * w / np.sqrt(2.0)
    errs = []
    for dt in (1e-3, 5e-4):
        case = _case([{"name": "R", "type": "rms", "quantity": VEL}], t_end=2 * 2 * np.pi / w,
                     over=["design.variables[1].value=0.0", f"integrator.dt={dt}"])
        errs.append(abs(dynsens.run_case(case, sensitivities=False).responses["R"].value / exact - 1))
    assert errs[0] < 1e-5 and 3.5 < errs[0] / errs[1] < 4.5, errs


@pytest.mark.parametrize("events", [None, EVENT], ids=["window", "event"])
def test_rms_gradient_matches_complex_step_and_the_adjoint(events):
    resp = [{"name": "R", "type": "rms", "quantity": DISP}, {"name": "Rv", "type": "rms", "quantity": VEL}]
    direct = dynsens.run_case(_case(resp, events=events, over=["sensitivity.method=direct"]))
    if events:     # the event ends the run: T moves with the design
        assert direct.responses["R"].value > 0 and "far" in direct.events
    cs = complex_step_gradients(_case(resp, events=events))
    adjoint = dynsens.run_case(_case(resp, events=events, over=["sensitivity.method=adjoint"]))
    assert adjoint.method == "adjoint"
    for name in ("R", "Rv"):
        assert rel_err(direct.responses[name].gradient, cs[name]) < 1e-9, name
        assert rel_err(adjoint.responses[name].gradient, direct.responses[name].gradient) < 1e-10, name


def test_rms_input_errors_and_the_type_list():
    with pytest.raises(CaseError) as exc:
        _case([{"name": "R", "type": "rms"}])
    assert "sdof.yaml" in str(exc.value) and "responses[0]" in str(exc.value) and "quantity" in str(exc.value)
    with pytest.raises(CaseError) as exc:
        _case([{"name": "R", "type": "rmss", "quantity": DISP}])
    assert "did you mean 'rms'" in str(exc.value) and "integral, rms, event_time" in str(exc.value), str(exc.value)
