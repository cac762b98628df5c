"""Every key a case file accepts: the one table the loaders check against and the reference and
JSON Schema are generated from (``python -m dynsens.case.schema --write``).

A :class:`Section` is one mapping of the case language (``integrator``, a response of type
``ks``, a multibody joint, ...).  Its :class:`Key` entries give the key's name, what it takes,
whether it is required, its default and a one-line meaning with units.  Sections that differ by
their ``type`` key (responses, elements, forces, time functions) are variants of a family.
This module imports nothing from dynsens, so every loader may import it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# what a key takes (the schema and the reference render these):
#   number   a number                      expr     a number or an expression of the design
#   string   text                          name     an identifier-like name
#   bool     true / false                  integer  an integer
#   enum     one of ``values``             vector   a list of numbers or expressions
#   list     a list of ``item`` (a section, or a kind above)
#   map      a mapping name -> ``item``     section  the mapping ``item``
#   any      anything the loader interprets (see the meaning)
KINDS = ("number", "expr", "string", "name", "bool", "integer", "enum", "vector", "list", "map", "section", "any")
NO_DEFAULT = object()


@dataclass(frozen=True)
class Key:
    """One key of a section."""

    name: str
    kind: str
    doc: str
    required: bool = False
    default: Any = NO_DEFAULT
    values: tuple[Any, ...] = ()      # enum values
    item: str | tuple[str, ...] | None = None   # section(s) or kind of list items / map values / section
    length: int | None = None         # vectors of a fixed length


@dataclass(frozen=True)
class Section:
    """One mapping of the case language."""

    title: str
    doc: str
    keys: tuple[Key, ...]
    type_value: str | None = None     # for a variant: the value of its ``type`` key
    open_ended: bool = False          # names chosen by the user (bodies, nodes, markers) map to items
    extra: dict[str, Any] = field(default_factory=dict)


def _k(name: str, kind: str, doc: str, **kw: Any) -> Key:
    return Key(name, kind, doc, **kw)


def _req(name: str, kind: str, doc: str, **kw: Any) -> Key:
    return Key(name, kind, doc, required=True, **kw)


TIME_FUNCTION_TYPES = ("constant", "step", "ramp", "smoothstep", "harmonic", "pulse", "table")
AGGREGATE_TYPES = ("ks", "max", "min", "stress_ratio", "buckling_ratio", "displacement_limit")
RESPONSE_TYPES = ("value", *AGGREGATE_TYPES, "integral", "event_time", "end_time", "mass", "expression")
STRUCTURAL_ELEMENT_TYPES = ("mass", "spring", "damper", "bar", "beam")
BEAM_SECTION_SHAPES = ("tube", "rectangle", "box", "properties")
FORCE_TYPES = ("point_force", "torque", "spring_damper", "rotational_spring_damper", "hydraulic_cylinder")
JOINT_TYPES = ("revolute", "prismatic", "spherical", "cylindrical", "fixed", "planar_pin")

_RESPONSE_COMMON = (
    _req("name", "name", "response name (an identifier); later expressions and the optimization refer to it"),
    _req("type", "enum", "response type", values=RESPONSE_TYPES),
    _k("unit", "string", "unit shown in reports and stored in the result file (default: the quantity's)"),
)
_AGGREGATE_KEYS = (
    *_RESPONSE_COMMON,
    _k("quantity", "any", "one quantity (or give `quantities`)"),
    _k("quantities", "list", "several quantities aggregated together", item="any"),
    _k("components", "any", "components taken: a list of labels or indices (one list per quantity with "
                            "`quantities`; null: all)", default="all"),
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

SECTIONS: dict[str, Section] = {
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
    )),
    "design": Section("design", "The design variables x.", (
        _k("variables", "list", "one entry per design variable, in the order of x", item="design.variable"),
        _k("families", "list", "families of per-element variables A[element], appended after `variables` "
           "(see the README, Per-member design variables)", item="design.family"),
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
        _req("assign", "map", "element key -> expression of the family name (NAME stands for NAME[element])",
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
        "README, Adaptive time steps); the gradient is exact along the accepted steps.", (
            _k("rtol", "number", "relative tolerance of the local error per step (> 0)", default=1e-4),
            _k("atol", "number", "absolute tolerance of the local error per step, in each coordinate's unit (> 0)",
               default=1e-8),
            _k("dt_min", "number", "smallest step (s); a step that still fails there stops the run with an error",
               default="1e-6 dt"),
            _k("dt_max", "number", "largest step (s); it also bounds the spacing of the output samples",
               default="t_end - t0"),
        )),
    "integrator.solver": Section("integrator.solver", "Newton–Raphson convergence test per block of z.", (
        _k("rtol", "number", "relative tolerance on the correction", default=1e-10),
        _k("atol", "number", "absolute tolerance on the correction", default=0.0),
        _k("max_iterations", "integer", "iterations per step before a step cut", default=25),
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
        _k("component", "any", "a component or a list of them: index or label", default="all"),
        _k("unit", "string", "unit shown in plots and stored in the file (default: the quantity's)"),
        _k("label", "string", "label for plots (default: the name)"),
        _k("sensitivity", "bool", "also store the design gradient at every step", default=False),
    )),
    "event": Section("events[i]", "An event ends the run when its quantity crosses `value`.", (
        _req("name", "name", "event name (responses refer to it)"),
        _req("quantity", "any", "the watched quantity (see Quantities)"),
        _k("component", "any", "component of a vector quantity: index or label", default=0),
        _req("value", "expr", "level"),
        _k("direction", "enum", "crossing direction", values=("rising", "falling", "either"), default="either"),
        _k("action", "enum", "what the event does", values=("terminate",), default="terminate"),
        _k("location", "enum", "crossing inside the step, or the first step past it",
           values=("interpolate", "step"), default="integrator.event_location"),
    )),
    "optimization": Section("optimization", "Objective and constraints for `dynsens optimize`.", (
        _req("objective", "name", "response to minimize"),
        _k("constraints", "list", "lower <= response <= upper", item="optimization.constraint"),
        _k("method", "enum", "optimizer", values=("SLSQP",), default="SLSQP"),
        _k("maxiter", "integer", "SLSQP iterations", default=100),
        _k("ftol", "number", "SLSQP tolerance on the scaled objective", default=1e-6),
    )),
    "optimization.constraint": Section("optimization.constraints[i]", "One constraint (either bound may be omitted; "
                                       "lower == upper is an equality).", (
        _req("response", "name", "constrained response"),
        _k("lower", "number", "lower bound (the response's unit)"),
        _k("upper", "number", "upper bound"),
    )),
    # ------------------------------------------------------------------ responses
    "response.value": Section("responses[i], type: value", "A quantity at the end, at a time or at an event.", (
        *_RESPONSE_COMMON,
        _req("quantity", "any", "the quantity (see Quantities)"),
        _k("component", "any", "component of a vector quantity: index or label", default=0),
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
                                       "load π²EI/(KL)²) of bars with `inertia`, aggregated over the elements and "
                                       "the run.", _RATIO_KEYS, type_value="buckling_ratio"),
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
        _k("component", "any", "component of a vector quantity: index or label", default=0),
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
    # ------------------------------------------------------------------ structural models
    "model.structural": Section("model (type: structural)", "Point masses, springs, dampers, truss bars and "
                                "plane beams on scalar DOFs or nodes.", (
        _req("type", "enum", "model kind", values=("structural",)),
        _k("dim", "enum", "node dimension", values=(2, 3), default=2),
        _k("dofs", "list", "scalar DOF names", item="name"),
        _k("nodes", "map", "node name -> {coords, fixed}; DOFs are named node.x, node.y (node.z)",
           item="structural.node"),
        _k("elements", "list", "elements", item=tuple(f"structural.{t}" for t in STRUCTURAL_ELEMENT_TYPES)),
        _k("loads", "list", "external loads", item="structural.load"),
        _k("initial", "section", "initial displacement and velocity", item="structural.initial"),
        _k("damping", "section", "Rayleigh damping", item="structural.damping"),
        _k("linear_algebra", "enum", "solver storage (auto: sparse above 200 DOFs)",
           values=("auto", "dense", "sparse"), default="auto"),
    )),
    "structural.node": Section("model.nodes.NAME", "A node.", (
        _req("coords", "vector", "coordinates (length dim)"),
        _k("fixed", "any", "'all' or a list of directions x, y, z (and rz at a beam node; rx, ry, rz in 3D) "
                           "held at zero"),
    )),
    "structural.mass": Section("elements[i], type: mass", "A point mass on a DOF, or on every direction of a node.", (
        _req("type", "enum", "element type", values=("mass",)),
        _k("name", "name", "element name"), _k("dof", "name", "the DOF"), _k("node", "name", "or a node"),
        _req("mass", "expr", "mass"),
    ), type_value="mass"),
    "structural.spring": Section("elements[i], type: spring", "f = k δ + k2 δ² + k3 δ³ between two DOFs.", (
        _req("type", "enum", "element type", values=("spring",)), _k("name", "name", "element name"),
        _req("dofs", "list", "[a, b]; b may be 'ground'", item="name"),
        _req("k", "expr", "linear stiffness"), _k("k2", "expr", "quadratic stiffness", default=0.0),
        _k("k3", "expr", "cubic stiffness", default=0.0),
    ), type_value="spring"),
    "structural.damper": Section("elements[i], type: damper", "f = c δ̇ between two DOFs, or nonlinear "
                                 "f = c δ̇ (δ̇² + ε²)^((α−1)/2) with `exponent` and `regularization`.", (
        _req("type", "enum", "element type", values=("damper",)), _k("name", "name", "element name"),
        _req("dofs", "list", "[a, b]; b may be 'ground'", item="name"), _req("c", "expr", "damping coefficient"),
        _k("exponent", "expr", "velocity exponent α > 0 (nonlinear damper; give with `regularization`)"),
        _k("regularization", "expr", "velocity ε > 0 that smooths the law at δ̇ = 0 (nonlinear damper)"),
    ), type_value="damper"),
    "structural.bar": Section("elements[i], type: bar", "Geometrically nonlinear truss bar (Green–Lagrange strain).", (
        _req("type", "enum", "element type", values=("bar",)), _k("name", "name", "element name"),
        _req("nodes", "list", "[node_1, node_2]", item="name"), _req("area", "expr", "cross-section area"),
        _req("E", "expr", "Young's modulus"), _k("density", "expr", "density (lumped mass)", default=0.0),
        _k("inertia", "expr", "second moment of area I (needed by the buckling quantity and response)"),
        _k("effective_length_factor", "expr", "K of the Euler load π²EI/(KL)²", default=1.0),
    ), type_value="bar"),
    "structural.beam": Section("elements[i], type: beam", "Plane co-rotational Euler–Bernoulli beam between two "
                               "nodes (x, y, θz each) in dim 2; in dim 3 a space-frame beam, small rotations "
                               "(x, y, z, θx, θy, θz each).", (
        _req("type", "enum", "element type", values=("beam",)), _k("name", "name", "element name"),
        _req("nodes", "list", "[node_1, node_2]", item="name"), _req("E", "expr", "Young's modulus"),
        _k("density", "expr", "density", default=0.0),
        _k("G", "expr", "shear modulus (3D beams: torsion GJ; required there)"),
        _k("kinematics", "enum", "3D beams: small rotations (linear), or corotational (large displacements and "
                                 "rotations, lumped mass)", values=("small", "corotational"), default="small"),
        _k("orientation", "vector", "3D beams: a vector in the local x–y plane, giving local y (the section's "
                                    "h direction)", length=3, default="global z; global y for a beam along z"),
        _req("section", "section", "cross-section", item="structural.beam_section"),
        _k("mass", "enum", "lumped, or consistent (turns with the element)", values=("lumped", "consistent"),
           default="lumped"),
    ), type_value="beam"),
    "structural.beam_section": Section("elements[i].section (beam)", "Cross-section: a shape and its "
                                       "dimensions (tube: D, t; rectangle: b, h; box: b, h, t; properties: "
                                       "A, I, c in 2D, A, Iy, Iz, J, cy, cz in 3D).", (
        _k("shape", "enum", "section shape", values=BEAM_SECTION_SHAPES, default="properties"),
        _k("D", "expr", "outer diameter (tube)"), _k("t", "expr", "wall thickness (tube, box)"),
        _k("b", "expr", "width (rectangle, box)"), _k("h", "expr", "height (rectangle, box)"),
        _k("A", "expr", "area (properties)"), _k("I", "expr", "second moment of area (properties)"),
        _k("c", "expr", "distance of the extreme fibre from the axis (properties)"),
        _k("Iy", "expr", "3D properties: second moment about local y (bending in the x–z plane)"),
        _k("Iz", "expr", "3D properties: second moment about local z (bending in the x–y plane)"),
        _k("J", "expr", "3D properties: torsion constant"),
        _k("cy", "expr", "3D properties: extreme-fibre distance along local y"),
        _k("cz", "expr", "3D properties: extreme-fibre distance along local z"),
    )),
    "structural.load": Section("model.loads[i]", "value · function(t) on a DOF or a node direction.", (
        _k("dof", "name", "the DOF"), _k("node", "name", "or a node"),
        _k("direction", "enum", "the node's direction (rx, ry, rz: a moment at a beam node, rx and ry in 3D; a "
                                "follower load: its local x or y)", values=("x", "y", "z", "rx", "ry", "rz")),
        _req("value", "expr", "amplitude"),
        _k("function", "any", "time function: a name or a mapping (see Time functions)", default="constant"),
        _k("follower", "bool", "the force turns with the rotation of its (beam) node", default=False),
    )),
    "structural.initial": Section("model.initial", "Initial state (DOF name -> value).", (
        _k("displacement", "map", "DOF -> initial displacement", item="expr"),
        _k("velocity", "map", "DOF -> initial velocity", item="expr"),
    )),
    "structural.damping": Section("model.damping", "D += α M + β K(q = 0).", (
        _k("rayleigh", "section", "Rayleigh coefficients", item="structural.rayleigh"),
    )),
    "structural.rayleigh": Section("model.damping.rayleigh", "Rayleigh coefficients.", (
        _k("alpha", "expr", "mass-proportional (1/s)", default=0.0),
        _k("beta", "expr", "stiffness-proportional (s)", default=0.0),
    )),
    "structural.quantity": Section("quantity (structural)", "`{dof: NAME | [NAMES], kind}`, `{node: NAME, "
                                   "kind}` or `{element: NAME | [NAMES] | all, kind}`.", (
        _k("dof", "any", "DOF name(s)"), _k("element", "any", "element name(s) or 'all'"),
        _k("node", "name", "a node: its free translation DOFs x, y (z) (kinds displacement, velocity, "
                           "acceleration)"),
        _k("kind", "enum", "displacement | velocity | acceleration (DOFs); force | stress | strain | buckling "
                           "(elements; beams: force, stress; dampers: force)",
           values=("displacement", "velocity", "acceleration", "force", "stress", "strain", "buckling")),
    )),
    # ------------------------------------------------------------------ multibody models
    "model.multibody": Section("model (type: multibody)", "Rigid bodies (Euler parameters), joints, forces and "
                               "hydraulic states.", (
        _req("type", "enum", "model kind", values=("multibody",)),
        _k("units", "string", "free text naming the unit system (informative)"),
        _k("gravity", "vector", "gravitational acceleration [x, y, z]", length=3),
        _req("bodies", "map", "body name -> body ('ground' has only markers)", item="multibody.body"),
        _k("joints", "list", "joints, distance rods and drivers",
           item=("multibody.joint", "multibody.distance_joint", "multibody.driver")),
        _k("forces", "list", "force elements", item=tuple(f"multibody.{t}" for t in FORCE_TYPES)),
        _k("initial", "section", "consistent initial assembly", item="multibody.initial"),
        _k("stabilization", "section", "Baumgarte terms (part of the residual)", item="multibody.stabilization"),
        _k("projection", "section", "project each step's end state onto the position and velocity "
                                    "constraints (recommended over Baumgarte)", item="multibody.projection"),
        _k("constraint_scale", "number", "multiplies the constraint rows", default=1.0),
        _k("drift_limit", "number", "bound on ‖Φ‖ beyond which a run stops", default="1e-2 × model size"),
        _k("linear_algebra", "enum", "storage of the linearization (auto: sparse from 200 step unknowns "
                                     "q, λ, p)", values=("auto", "dense", "sparse"), default="auto"),
    )),
    "multibody.body": Section("model.bodies.NAME", "A rigid body; numbers may be design expressions.", (
        _k("mass", "expr", "mass (required for moving bodies)"),
        _k("inertia", "vector", "[Ixx, Iyy, Izz] or [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] about the COM, body axes"),
        _k("position", "vector", "COM at t0 (a guess; the assembly closes the loops)", length=3),
        _k("orientation", "section", "initial orientation", item=("multibody.orientation.axis_angle",
                                                                 "multibody.orientation.euler")),
        _k("velocity", "vector", "COM velocity (global)", length=3),
        _k("angular_velocity", "vector", "angular velocity (global)", length=3),
        _k("markers", "map", "marker name -> [x, y, z] (body axes from the COM) or {position, frame}",
           item="multibody.marker"),
        _k("point_mass", "bool", "a point mass: no inertia, orientation held fixed; joints only at its "
           "mass point (keys: mass, position, velocity, markers)", default=False),
    )),
    "multibody.orientation.axis_angle": Section("orientation (axis and angle)", "Rotation about an axis.", (
        _k("axis", "vector", "rotation axis", length=3, default=[0, 0, 1]),
        _req("angle", "expr", "angle (rad)"),
    )),
    "multibody.orientation.euler": Section("orientation (Euler parameters)", "Given Euler parameters.", (
        _req("euler_parameters", "vector", "[e0, e1, e2, e3]", length=4),
    )),
    "multibody.marker": Section("markers.NAME (mapping form)", "A marker given with its frame.", (
        _req("position", "vector", "coordinates", length=3),
        _k("frame", "enum", "body axes from the COM, or global coordinates at t0", values=("body", "global"),
           default="body"),
    )),
    "multibody.joint": Section("joints[i]", "A joint between two bodies.", (
        _k("name", "name", "joint name (quantities refer to it)"),
        _req("type", "enum", "joint type", values=JOINT_TYPES),
        _req("body_1", "name", "first body (or ground)"), _req("body_2", "name", "second body"),
        _k("point", "any", "joint point: a marker name or [x, y, z] global at t0 (instead of markers)"),
        _k("marker_1", "name", "the joint point on body 1"), _k("marker_2", "name", "the joint point on body 2"),
        _k("axis", "vector", "joint axis (global at t0)", length=3),
    )),
    "multibody.driver": Section("joints[i], type: driving", "Prescribed motion of a joint coordinate or of a body's "
                                "COM: offset + rate·t + amplitude·sin(2π·frequency·t + phase).", (
        _k("name", "name", "driver name"), _req("type", "enum", "driver", values=("driving",)),
        _k("joint", "name", "the driven revolute (angle) or prismatic (slide) joint"),
        _k("body", "name", "or the body whose COM coordinate is driven"),
        _k("coordinate", "enum", "angle | slide (joint) or x | y | z (body)", values=("angle", "slide", "x", "y", "z")),
        _k("distance", "any", "or the distance between two markers: [body_1.marker_1, body_2.marker_2]"),
        _k("expression", "string", "the prescribed value as an expression of t and the design variables "
           "(instead of offset, rate, amplitude, frequency, phase)"),
        _k("offset", "expr", "value at t = 0 (default: the initial one)"),
        _k("rate", "expr", "rate", default=0.0), _k("amplitude", "expr", "amplitude", default=0.0),
        _k("frequency", "expr", "frequency (Hz)", default=0.0), _k("phase", "expr", "phase (rad)", default=0.0),
    )),
    "multibody.distance_joint": Section("joints[i], type: distance", "A massless rod: the distance between two "
                                        "markers is held at `length`.", (
        _k("name", "name", "joint name"), _req("type", "enum", "joint type", values=("distance",)),
        _req("body_1", "name", "first body (or ground)"), _req("body_2", "name", "second body"),
        _req("marker_1", "name", "marker on body 1"), _req("marker_2", "name", "marker on body 2"),
        _req("length", "expr", "rod length"),
    ), type_value="distance"),
    "multibody.point_force": Section("forces[i], type: point_force", "A force at a marker.", (
        _req("type", "enum", "force type", values=("point_force",)), _k("name", "name", "force name"),
        _req("body", "name", "body"), _k("point", "name", "marker (default: the COM)"),
        _req("force", "vector", "[Fx, Fy, Fz]", length=3),
        _k("frame", "enum", "components in global or body axes", values=("global", "body"), default="global"),
        _k("function", "any", "time function multiplying the force", default="constant"),
    ), type_value="point_force"),
    "multibody.torque": Section("forces[i], type: torque", "A torque on a body.", (
        _req("type", "enum", "force type", values=("torque",)), _k("name", "name", "force name"),
        _req("body", "name", "body"), _req("torque", "vector", "[Mx, My, Mz]", length=3),
        _k("frame", "enum", "components in global or body axes", values=("global", "body"), default="global"),
        _k("function", "any", "time function multiplying the torque", default="constant"),
    ), type_value="torque"),
    "multibody.spring_damper": Section("forces[i], type: spring_damper", "Axial spring-damper between two markers: "
                                       "f = k(L − L0) + k3(L − L0)³ + d L̇.", (
        _req("type", "enum", "force type", values=("spring_damper",)), _k("name", "name", "force name"),
        _req("body_1", "name", "body 1"), _req("point_1", "name", "marker on body 1"),
        _req("body_2", "name", "body 2"), _req("point_2", "name", "marker on body 2"),
        _k("stiffness", "expr", "k", default=0.0), _k("cubic_stiffness", "expr", "k3", default=0.0),
        _k("damping", "expr", "d", default=0.0), _k("free_length", "expr", "L0 (default: the initial length)"),
    ), type_value="spring_damper"),
    "multibody.rotational_spring_damper": Section("forces[i], type: rotational_spring_damper",
                                                  "Torque −k(φ − φ0) − d φ̇ about an axis between two bodies.", (
        _req("type", "enum", "force type", values=("rotational_spring_damper",)), _k("name", "name", "force name"),
        _req("body_1", "name", "body 1 (or ground)"), _req("body_2", "name", "body 2"),
        _req("axis", "vector", "axis (global at t0)", length=3),
        _k("stiffness", "expr", "k (torque per rad)", default=0.0), _k("damping", "expr", "d", default=0.0),
        _k("free_angle", "expr", "φ0 (rad)", default=0.0),
    ), type_value="rotational_spring_damper"),
    "multibody.hydraulic_cylinder": Section("forces[i], type: hydraulic_cylinder", "Two-chamber cylinder between two "
                                            "markers; its chamber pressures are first-order states.", (
        _req("type", "enum", "force type", values=("hydraulic_cylinder",)), _k("name", "name", "force name"),
        _req("body_1", "name", "barrel body"), _req("point_1", "name", "barrel pivot marker"),
        _req("body_2", "name", "rod body"), _req("point_2", "name", "rod eye marker"),
        _k("bore", "expr", "piston diameter (or give area_1)"), _k("rod", "expr", "rod diameter (or give area_2)"),
        _k("area_1", "expr", "piston-side area"), _k("area_2", "expr", "rod-side area"),
        _req("length_0", "expr", "pin-to-pin length at zero stroke"), _req("stroke_max", "expr", "stroke"),
        _req("bulk_modulus", "expr", "effective bulk modulus"),
        _req("dead_volume_1", "expr", "piston-side dead (line) volume"),
        _req("dead_volume_2", "expr", "rod-side dead (line) volume"),
        _k("tank_conductance", "expr", "laminar return-line conductance (rod side to tank)", default=0.0),
        _k("tank_pressure", "expr", "tank pressure", default=0.0),
        _k("damping", "expr", "viscous damping on the stroke rate", default=0.0),
        _req("pump_flow", "expr", "pump flow into the piston side (volume per time)"),
        _k("pump_function", "any", "time function multiplying the pump flow", default="constant"),
        _k("initial_pressures", "any", "'static' (p1 holds the load, p2 = tank), or [p1 | static, p2]",
           default="static"),
    ), type_value="hydraulic_cylinder"),
    "multibody.initial": Section("model.initial", "The initial assembly (closes the loops consistently).", (
        _k("hold", "list", "coordinates kept as given, e.g. rack.angle_z", item="string"),
        _k("distances", "list", "prescribed distances between markers", item="multibody.distance"),
        _k("time", "number", "time of the assembly", default=0.0),
        _k("tolerance", "number", "assembly tolerance", default=1e-12),
    )),
    "multibody.distance": Section("model.initial.distances[i]", "A prescribed distance.", (
        _req("between", "list", "[body.marker, body.marker]", item="string"),
        _req("value", "expr", "distance"),
    )),
    "multibody.stabilization": Section("model.stabilization", "Baumgarte stabilization of the constraint drift.", (
        _k("alpha", "number", "velocity-level coefficient (1/s)", default=0.0),
        _k("beta", "number", "position-level coefficient (1/s)", default=0.0),
    )),
    "multibody.projection": Section("model.projection", "Projection of each accepted step's (q, q̇) onto "
                                    "Φ = 0 and Φ̇ = 0 (closest point, plain 2-norm); the sensitivities are "
                                    "projected consistently.", (
        _k("enabled", "bool", "switch the projection on (writing the section switches it on)", default=True),
        _k("tol", "number", "bound on the last Newton correction, relative to 1 + ‖q‖", default=1e-13),
        _k("max_iterations", "integer", "iterations before the run stops with an error", default=12),
        _k("mode", "enum", "output: the run continues from the solved (index-1) state and reports the "
                           "projected one; state: it continues from the projected state", default="output",
           values=("state", "output")),
    )),
    "multibody.quantity": Section("quantity (multibody)", "Exactly one of joint, body, marker, element, with `kind`.", (
        _k("joint", "name", "joint: reaction_force | reaction_force_norm | reaction_moment | "
                            "reaction_force_joint_frame | multipliers"),
        _k("body", "name", "body: position | velocity | acceleration | angle_z | angular_velocity | "
                           "angular_velocity_z"),
        _k("marker", "string", "body.marker: position | velocity"),
        _k("element", "name", "cylinder: stroke | stroke_rate | pressure_1 | pressure_2 | force | volume_1 | "
                              "volume_2; spring_damper: length | length_rate | force"),
        _req("kind", "string", "what to read (by the head key, above)"),
    )),
}


def allowed(section: str, *extra: str) -> tuple[str, ...]:
    """The keys ``section`` accepts (plus ``extra``), in table order."""
    return tuple(k.name for k in SECTIONS[section].keys) + extra


def required(section: str) -> tuple[str, ...]:
    """The keys ``section`` requires."""
    return tuple(k.name for k in SECTIONS[section].keys if k.required)
