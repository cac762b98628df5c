"""The sections of the case file that every model shares: the top level, the design, the
integrator, sensitivities, outputs, events, the optimization, the responses and time functions."""
from __future__ import annotations

from .keys import RESPONSE_TYPES, TIME_FUNCTION_TYPES, Section, _k, _req

_RESPONSE_COMMON = (
    _req("name", "name", "response name (an identifier); later expressions and the optimization refer to it"),
    _req("type", "enum", "response type", values=RESPONSE_TYPES),
    _k("unit", "string", "unit shown in reports and stored in the result file (default: the quantity's)"),
)
#: how every key that picks a component reads a label
_LABEL = ("a label in full (`u10.displacement`, `Z.fx`) or, where it names one component, its first or last "
          "part (`u10`, `fx`)")
_AGGREGATE_KEYS = (
    *_RESPONSE_COMMON,
    _k("quantity", "any", "one quantity (or give `quantities`)"),
    _k("quantities", "list", "several quantities aggregated together", item="any"),
    _k("components", "any", "components taken: a list of labels or indices (one list per quantity with "
                            "`quantities`; null: all); " + _LABEL, default="all"),
    _k("absolute", "bool", "aggregate |value| (both signs)", default=False),
    _k("limit", "expr", "divide by this positive constant (the response becomes a ratio, unit '-')", default=1.0),
)
_RATIO_KEYS = (
    *_RESPONSE_COMMON,
    _k("elements", "any", "all, an element name or a list of them", default="all"),
    _k("aggregate", "enum", "KS (smooth) or the sampled maximum", values=("ks", "max"), default="ks"),
    _k("rho", "number", "KS parameter (required with aggregate: ks)"),
)
_TF_TYPE = _req("type", "enum", "time function", values=TIME_FUNCTION_TYPES)

GENERAL_SECTIONS: dict[str, Section] = {
    # ------------------------------------------------------------------ the case
    "case": Section("Case file (top level)", "A case is one YAML mapping with these keys.", (
        _k("name", "string", "case name (default: the file name)"),
        _k("description", "string", "free text"),
        _k("design", "section", "design variables", item="design"),
        _req("model", "section", "the model: `type: structural` or `type: multibody`",
             item=("model.structural", "model.multibody")),
        _req("integrator", "section", "time integration", item="integrator"),
        _k("sensitivity", "section", "design sensitivities", item="sensitivity"),
        _k("output", "section", "what the result file stores", item="output"),
        _k("events", "list", "events that end the run when a quantity crosses a level", item="event"),
        _k("responses", "list", "responses: values, maxima, integrals, event times, expressions",
           item=tuple(f"response.{t}" for t in RESPONSE_TYPES)),
        _k("optimization", "section", "objective and constraints for `dynsens optimize`", item="optimization"),
        _k("load_cases", "map", "named load cases: name -> {key path: value}, each the case with these "
           "overrides of model.loads, model.forces, model.initial, integrator.t_end or integrator.dt; "
           "responses become RESPONSE@NAME; simulate, optimize and check-gradients run every load case "
           "(see docs/load_cases.md)", item="any"),
    )),
    "design": Section("design", "The design variables x.", (
        _k("variables", "list", "one entry per design variable, in the order of x", item="design.variable"),
        _k("families", "list", "families of per-element variables A[element], appended after `variables` "
           "(see docs/case-files.md, Per-member design variables)", item="design.family"),
    )),
    "design.family": Section("design.families[i]", "One variable per selected element, named NAME[element].", (
        _req("name", "name", "family name; its members are NAME[element]"),
        _k("elements", "any", "all, a list of element names, or a glob pattern such as 'diag*'", default="all"),
        _k("type", "enum", "element type selected", values=("bar", "beam", "spring", "damper", "mass"),
           default="bar"),
        _req("value", "number", "initial value shared by the members"),
        _k("lower", "number", "lower bound shared by the members", default="-inf"),
        _k("upper", "number", "upper bound shared by the members", default="inf"),
        _k("scale", "number", "typical magnitude shared by the members", default="|value|, or 1"),
        _req("assign", "map", "numeric element key (area, E, ...; a beam's section dimension or property as "
                                     "section.D, section.h, section.Iy, ...) -> expression of the family name "
                                     "(NAME stands for NAME[element])",
             item="expr"),
        _k("members", "map", "element name -> its own start, bounds or scale", item="design.family.member"),
    )),
    "design.family.member": Section("design.families[i].members.ELEMENT", "One member's own start and bounds.", (
        _k("value", "number", "initial value"), _k("lower", "number", "lower bound"),
        _k("upper", "number", "upper bound"), _k("scale", "number", "typical magnitude"),
    )),
    "design.variable": Section("design.variables[i]", "One design variable.", (
        _req("name", "name", "name used in expressions"),
        _req("value", "number", "initial value x0 (the case's units)"),
        _k("lower", "number", "lower bound (optimization, Latin-hypercube starts)", default="-inf"),
        _k("upper", "number", "upper bound", default="inf"),
        _k("scale", "number", "typical magnitude (relative finite-difference steps at x = 0; unbounded scaling)",
           default="|value|, or 1"),
        _k("unit", "string", "unit of the variable, shown in summaries and plots", default="''"),
    )),
    "integrator": Section("integrator", "Time integration and the Newton solver.", (
        _k("scheme", "enum", "Newmark-β, HHT-α or generalized-α", values=("newmark", "hht", "generalized_alpha"),
           default="newmark"),
        _k("beta", "number", "Newmark β (β < γ/2 warns: conditionally stable)", default=0.25),
        _k("gamma", "number", "Newmark γ (γ < 1/2 is rejected; γ > 1/2 warns: first order)", default=0.5),
        _k("alpha", "number", "HHT α in [0, 1/3] (scheme hht only)", default=0.05),
        _k("rho_inf", "number", "spectral radius at infinity in [0, 1] (scheme generalized_alpha only)"),
        _req("dt", "number", "time step (s, or the case's time unit)"),
        _k("t0", "number", "start time", default=0.0),
        _req("t_end", "number", "end time (an event may end the run earlier)"),
        _k("solver", "section", "Newton tolerances", item="integrator.solver"),
        _k("event_location", "enum", "default for events: crossing inside the step, or the first step past it",
           values=("interpolate", "step"), default="interpolate"),
        _k("max_step_cuts", "integer", "how often a step whose Newton iteration fails is halved (0..30)",
           default=6),
        _k("adaptive", "section", "adaptive steps by a local error estimate (dt: the first step)",
           item="integrator.adaptive"),
    )),
    "integrator.adaptive": Section(
        "integrator.adaptive", "Step sizes chosen by the local error estimate of the Newmark family (see the "
        "docs/case-files.md, Adaptive time steps); the gradient is exact along the accepted steps.", (
            _k("rtol", "number", "relative tolerance of the local error per step (> 0)", default=1e-4),
            _k("atol", "number", "absolute tolerance of the local error per step, in each coordinate's unit (> 0)",
               default=1e-8),
            _k("dt_min", "number", "smallest step (s); a step that still fails there stops the run with an error",
               default="1e-6 dt"),
            _k("dt_max", "number", "largest step (s); it also bounds the spacing of the output samples",
               default="t_end - t0"),
        )),
    "integrator.solver": Section("integrator.solver", "Newton–Raphson convergence test per block of z.", (
        _k("rtol", "number", "relative tolerance on the correction (> 0)", default=1e-10),
        _k("atol", "number", "absolute tolerance on the correction (>= 0)", default=0.0),
        _k("max_iterations", "integer", "iterations per step before a step cut (>= 1)", default=25),
    )),
    "sensitivity": Section("sensitivity", "Design sensitivities: direct differentiation or the adjoint.", (
        _k("enabled", "bool", "compute gradients", default=True),
        _k("partials", "enum", "numerical partials ∂F_R/∂x at fixed state", values=("forward", "central", "complex"),
           default="forward"),
        _k("step", "number", "relative step of the partials", default="1e-8 / 1e-5 / 1e-20 (by method)"),
        _k("matrix", "enum", "reuse the last Newton factor (error below the partials') or refactorize at the "
                             "solution", values=("reuse", "converged"), default="reuse"),
        _k("method", "enum", "derivative mode: direct differentiation, the discrete adjoint, or chosen by the "
                             "counts of design variables and responses", values=("direct", "adjoint", "auto"),
           default="direct"),
        _k("memory_budget", "any", "memory the adjoint may keep for its step records (bytes, or with a unit such "
                                   "as 500 MB); beyond it, checkpoints and recomputed segments", default="2 GiB"),
    )),
    "output": Section("output", "What `dynsens simulate` writes besides responses and gradients.", (
        _k("history", "any", "state histories: a list from q qd qdd lam p pd, or 'all' or 'none'",
           default="[q, qd, qdd]"),
        _k("sensitivity_history", "bool", "store the (N, n, m) sensitivity histories too", default=False),
        _k("quantities", "list", "quantities recorded over time with unit and label (see Recorded quantities)",
           item="output.quantity"),
    )),
    "output.quantity": Section("output.quantities[i]", "A quantity recorded at every step.", (
        _req("name", "name", "name of the recorded series (an identifier)"),
        _req("quantity", "any", "the quantity (see Quantities), as responses and events name it"),
        _k("component", "any", "a component or a list of them: index or label; " + _LABEL, default="all"),
        _k("unit", "string", "unit shown in plots and stored in the file (default: the quantity's)"),
        _k("label", "string", "label for plots (default: the name)"),
        _k("sensitivity", "bool", "also store the design gradient at every step", default=False),
    )),
    "event": Section("events[i]", "An event ends the run when its quantity crosses `value`.", (
        _req("name", "name", "event name (responses refer to it)"),
        _req("quantity", "any", "the watched quantity (see Quantities)"),
        _k("component", "any", "component of a vector quantity: index or label; " + _LABEL, default=0),
        _req("value", "expr", "level"),
        _k("direction", "enum", "crossing direction", values=("rising", "falling", "either"), default="either"),
        _k("action", "enum", "what the event does", values=("terminate",), default="terminate"),
        _k("location", "enum", "crossing inside the step, or the first step past it",
           values=("interpolate", "step"), default="integrator.event_location"),
    )),
    "optimization": Section("optimization", "Objective and constraints for `dynsens optimize`.", (
        _req("objective", "name", "response to minimize (with load_cases: RESPONSE@LOADCASE)"),
        _k("constraints", "list", "lower <= response <= upper", item="optimization.constraint"),
        _k("method", "enum", "optimizer: SLSQP (dense quasi-Newton, tens of variables), MMA or CCSAQ (Svanberg's "
           "moving asymptotes, many variables; `pip install 'dynsens[mma]'`), trust-constr (interior point), "
           "IPOPT (interior point, limited-memory Hessian, many variables; "
           "the Ipopt library and `pip install 'dynsens[ipopt]'`)",
           values=("SLSQP", "MMA", "CCSAQ", "trust-constr", "IPOPT"), default="SLSQP"),
        _k("maxiter", "integer", "iterations of the optimizer", default=100),
        _k("ftol", "number", "tolerance on the scaled objective (MMA: its relative change; trust-constr: the "
           "optimality measure; IPOPT: its scaled KKT tolerance `tol`)", default=1e-6),
        _k("verification", "section", "the verification run at the optimum (on by default)",
           item="optimization.verification"),
    )),
    "optimization.verification": Section(
        "optimization.verification", "After the optimization, the optimum is run again at a refined step and "
        "on a longer window; every constraint and every member is checked in those runs (see "
        "docs/optimization.md).", (
            _k("enabled", "bool", "run the verification after `dynsens optimize`", default=True),
            _k("refine", "integer", "the refined run's step is dt/refine (at least 2)", default=2),
            _k("horizon", "any", "auto (extend the window by its length until the constrained peaks settle), "
               "none, or an end time (s) beyond t_end", default="auto"),
            _k("tail", "number", "a constrained peak in this last share of the window is reported (0: not "
               "checked)", default=0.1),
            _k("rounds", "integer", "re-optimize from the optimum with each failing bound tightened by the "
               "shortfall the verification measured (times `safety`), at most this many times", default=0),
            _k("safety", "number", "factor on the measured shortfall when a bound is tightened (>= 1)",
               default=1.5),
        )),
    "optimization.constraint": Section("optimization.constraints[i]", "One constraint (either bound may be omitted; "
                                       "lower == upper is an equality).", (
        _req("response", "name", "constrained response (with load_cases: RESPONSE@LOADCASE, or RESPONSE@all "
             "for one constraint per load case)"),
        _k("lower", "number", "lower bound (the response's unit)"),
        _k("upper", "number", "upper bound"),
    )),
    # ------------------------------------------------------------------ responses
    "response.value": Section("responses[i], type: value", "A quantity at the end, at a time or at an event.", (
        *_RESPONSE_COMMON,
        _req("quantity", "any", "the quantity (see Quantities)"),
        _k("component", "any", "component of a vector quantity: index or label; " + _LABEL, default=0),
        _k("at", "enum", "'end' (default) unless `time` or `event` is given", values=("end",), default="end"),
        _k("time", "number", "read at this time (interpolated inside the step)"),
        _k("event", "name", "read at this event"),
        _k("derivative", "enum", "at an event: total gradient, or with the event time held fixed",
           values=("total", "fixed_time"), default="total"),
    ), type_value="value"),
    "response.ks": Section("responses[i], type: ks", "Kreisselmeier–Steinhauser maximum (or minimum) over time "
                           "and components.", (
        *_AGGREGATE_KEYS,
        _req("rho", "number", "aggregation parameter (1/unit of the aggregated value); larger is closer to the "
                              "maximum"),
        _k("side", "enum", "smooth maximum (upper) or smooth minimum (lower)", values=("upper", "lower"),
           default="upper"),
    ), type_value="ks"),
    "response.max": Section("responses[i], type: max", "Sampled maximum over the steps and components "
                            "(gradient of the active sample).", _AGGREGATE_KEYS, type_value="max"),
    "response.min": Section("responses[i], type: min", "Sampled minimum over the steps and components.",
                            _AGGREGATE_KEYS, type_value="min"),
    "response.stress_ratio": Section("responses[i], type: stress_ratio", "σ/σ_t in tension and −σ/σ_c in "
                                     "compression (or |σ|/limit), aggregated over the elements and the run.", (
        *_RATIO_KEYS,
        _k("tension_limit", "expr", "allowable tensile stress σ_t (a positive constant)"),
        _k("compression_limit", "expr", "allowable compressive stress σ_c (a positive constant)"),
        _k("limit", "expr", "one allowable |σ| for both signs (instead of the two limits)"),
    ), type_value="stress_ratio"),
    "response.buckling_ratio": Section("responses[i], type: buckling_ratio", "−N/P_E (compression over the Euler "
                                       "load π²EI/(KL)²) of bars with `inertia` and of beams (3D beams: about "
                                       "each axis), aggregated over the elements and the run.", (
        *_RATIO_KEYS,
        _k("effective_length_factor", "expr", "K of the beams' Euler load π²EI/(KL)², L the beam element's "
                                              "length (bars take theirs from the element)", default=1.0),
    ), type_value="buckling_ratio"),
    "response.interaction_ratio": Section("responses[i], type: interaction_ratio", "Beam-column stability: "
                                          "AISC 360-16 Eq. H1-1a/b with the elastic strengths P_c = "
                                          "φ·min(π²EI/(KL)², F_y A) (tension φF_y A) and M_c = φF_y W, as "
                                          "max(p + 8/9 m, p/2 + m) (≤ 1 exactly where H1-1 holds), at both ends "
                                          "of every beam, aggregated over the beams and the run.", (
        *_RATIO_KEYS,
        _req("yield_stress", "expr", "F_y, a positive constant (the unit of the beams' stresses)"),
        _k("effective_length_factor", "expr", "K of the Euler load π²EI/(KL)², L the beam element's length",
           default=1.0),
        _k("resistance_factor", "expr", "φ in (0, 1] multiplying both strengths (LRFD: 0.9)", default=1.0),
    ), type_value="interaction_ratio"),
    "response.displacement_limit": Section("responses[i], type: displacement_limit", "|u|/limit, aggregated "
                                           "over the nodes (or DOFs) and the run: |u| is the length of a node's "
                                           "translation vector, or the absolute value of a DOF (both signs).", (
        *_RESPONSE_COMMON, *_RATIO_KEYS[len(_RESPONSE_COMMON) + 1:],     # aggregate, rho
        _k("nodes", "any", "a node name or a list of them: the length of each node's translation"),
        _k("dofs", "any", "a DOF name or a list of them: the absolute value of each (instead of `nodes`)"),
        _req("limit", "expr", "allowable |u| (a positive constant, the case's length unit)"),
    ), type_value="displacement_limit"),
    "response.integral": Section("responses[i], type: integral", "Trapezoid integral over the steps, of one "
                                 "quantity's component or of an expression of quantities.", (
        *_RESPONSE_COMMON,
        _k("quantity", "any", "the quantity (see Quantities); required unless `expression` is given"),
        _k("component", "any", "component of a vector quantity: index or label; " + _LABEL, default=0),
        _k("expression", "string", "integrand as an expression of `symbols` (instead of quantity/component)"),
        _k("symbols", "map", "symbol -> {quantity, component}: the quantities the expression names", item="any"),
    ), type_value="integral"),
    "response.event_time": Section("responses[i], type: event_time", "Time at which an event fires (missing if "
                                   "it never does).", (
        *_RESPONSE_COMMON,
        _req("event", "name", "the event"),
    ), type_value="event_time"),
    "response.end_time": Section("responses[i], type: end_time", "Time at which the run ends (t_end or the first "
                                 "event).", _RESPONSE_COMMON, type_value="end_time"),
    "response.mass": Section("responses[i], type: mass", "Total structural mass (structural models).",
                             _RESPONSE_COMMON, type_value="mass"),
    "response.frequency": Section("responses[i], type: frequency", "The lowest natural frequency (Hz) of a "
                                  "structural model at its initial state, or a smooth (KS) minimum of the lowest "
                                  "`modes` (see docs/optimization.md).", (
        *_RESPONSE_COMMON,
        _k("modes", "integer", "how many of the lowest modes the KS minimum takes (>= 1)", default=1),
        _k("rho", "number", "KS parameter, 1/Hz (required with modes > 1)"),
    ), type_value="frequency"),
    "response.buckling_factor": Section("responses[i], type: buckling_factor", "The lowest linear buckling load "
                                        "factor of the case's load (structural models), or a smooth (KS) minimum "
                                        "of the lowest `modes`.", (
        *_RESPONSE_COMMON,
        _k("modes", "integer", "how many of the lowest factors the KS minimum takes (>= 1)", default=1),
        _k("rho", "number", "KS parameter (required with modes > 1)"),
        _k("load_time", "number", "the load of this time (s) is the reference load (default: the instant "
           "of the window where it is largest)"),
    ), type_value="buckling_factor"),
    "response.expression": Section("responses[i], type: expression", "An expression of earlier responses and "
                                   "design variables.", (
        *_RESPONSE_COMMON,
        _req("expression", "string", "e.g. `ks_force + 0.01*V_S` (restricted evaluator)"),
    ), type_value="expression"),
    # ------------------------------------------------------------------ time functions
    "function.constant": Section("function: constant", "f(t) = 1.", (_TF_TYPE,), type_value="constant"),
    "function.step": Section("function: step", "0 before t0, 1 from t0.", (
        _TF_TYPE, _k("t0", "expr", "switch time", default=0.0)), type_value="step"),
    "function.ramp": Section("function: ramp", "linear from 0 at t0 to 1 at t1.", (
        _TF_TYPE, _k("t0", "expr", "start", default=0.0), _req("t1", "expr", "end")), type_value="ramp"),
    "function.smoothstep": Section("function: smoothstep", "3τ² − 2τ³ from t0 to t1.", (
        _TF_TYPE, _k("t0", "expr", "start", default=0.0), _req("t1", "expr", "end")), type_value="smoothstep"),
    "function.harmonic": Section("function: harmonic", "sin(2π f t + φ).", (
        _TF_TYPE, _req("frequency", "expr", "frequency (Hz)"), _k("phase", "expr", "phase (rad)", default=0.0)),
        type_value="harmonic"),
    "function.pulse": Section("function: pulse", "sin² pulse from t0 lasting `duration`.", (
        _TF_TYPE, _k("t0", "expr", "start", default=0.0), _req("duration", "expr", "duration")),
        type_value="pulse"),
    "function.table": Section("function: table", "piecewise linear through the points.", (
        _TF_TYPE, _req("t", "vector", "times, increasing"), _req("values", "vector", "values")),
        type_value="table"),
}
