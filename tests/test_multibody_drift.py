"""The drift guard's message names what was measured (‖Φ‖, the limit, the largest residual, the
conditioning of J_Φ) and suggests no setting that would only hide the failure; near a singular
pose it names the joints losing rank."""
from __future__ import annotations

import pytest

import dynsens
from conftest import CASES
from dynsens.errors import ModelError
from dynsens.models.multibody.drift import check_drift
from test_multibody_singular import _apex_state, _case


def _refuses_hiding(msg):
    for hint in ("drift_limit", "stabilization", "Baumgarte"):
        assert hint not in msg, hint


def test_plain_drift_is_measured_not_blamed_on_a_dead_centre():
    case = dynsens.load_case(CASES / "four_bar.yaml", overrides=["integrator.dt=0.05", "model.drift_limit=0.0001"])
    with pytest.raises(ModelError) as exc:
        dynsens.run_case(case, sensitivities=False)
    msg = str(exc.value)
    assert "‖Φ‖ = " in msg and "exceeds the limit 0.0001" in msg and "largest residual" in msg
    assert "σ_min/σ_max = " in msg and "J_Φ is regular at this pose" in msg
    assert "dead-centre" not in msg
    _refuses_hiding(msg)


def test_drift_at_a_singular_pose_names_the_joints(tmp_path):
    case = _case(tmp_path, 0.5)           # the drive reaches the apex y = 0.5 m at t = 1 s
    m = case.model
    m.drift_limit = 1e-3
    prm = m.parameters(case.x0)
    with pytest.raises(ModelError) as exc:
        check_drift(m, 0.9, _apex_state(m), prm)     # the drive wants y = 0.494 m there
    msg = str(exc.value)
    assert "t = 0.9 s" in msg and "The joints O, lift are (nearly) losing rank" in msg and "dead-centre" in msg
    _refuses_hiding(msg)
