"""'Leave out what the case does not need', shown by the run counters."""
import dynsens
from conftest import CASES


def test_linear_constant_case_factorizes_once():
    res = dynsens.run_case(dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=1"]))
    c = res.counters
    assert c["steps"] == 1000
    assert c["step_factorizations"] == 1          # one factorization for the whole run
    assert c["linearizations"] == 2               # t0 matrix and the time-step matrix, once each
    assert c["newton_iterations"] == c["steps"] + 1  # one solve per step, no Newton loop


def test_no_sensitivities_no_sensitivity_work():
    case = dynsens.load_case(CASES / "duffing_chain.yaml", ["integrator.t_end=0.2"])
    off = dynsens.run_case(case, sensitivities=False).counters
    on = dynsens.run_case(case).counters
    assert off["sensitivity_residual_evaluations"] == 0
    assert off["solve_columns"] == off["solves"]            # only vector right-hand sides
    assert on["sensitivity_residual_evaluations"] == (on["steps"] + 1) * 5   # m + 1 = 5 per step (forward)
    # sensitivities reuse the last Newton factorization; only a step accepted on a round-off
    # residual (its factor one full correction old) is factorized again: at most one per step
    assert on["factorizations"] - off["factorizations"] <= on["steps"] + 1
    exact = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.2", "sensitivity.matrix=converged"])).counters
    assert exact["factorizations"] - off["factorizations"] <= exact["steps"] + 1
    lin_on = dynsens.run_case(dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.t_end=0.2"])).counters
    assert lin_on["factorizations"] == 2        # linear: never more than the primal run's two


def test_only_requested_histories_are_stored():
    case = dynsens.load_case(CASES / "duffing_chain.yaml", ["integrator.t_end=0.05", "output.history=[q]"])
    res = dynsens.run_case(case)
    assert set(res.history) == {"q"} and res.sensitivity_history == {}
    res = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.05", "output.history=none"]))
    assert res.history == {}
    res = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.05", "output.history=[qd]", "output.sensitivity_history=true"]))
    assert res.sensitivity_history["qd"].shape == (51, 20, 4)


def test_dense_or_sparse_chosen_from_size():
    from scripts_path import duffing_chain
    small = dynsens.load_case_dict(duffing_chain(20, t_end=0.01))
    large = dynsens.load_case_dict(duffing_chain(300, t_end=0.01))
    assert not small.model.traits.sparse and large.model.traits.sparse
