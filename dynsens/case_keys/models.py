"""The sections of the two model kinds: structural models (nodes, elements, loads, damping) and
multibody models (bodies, joints, drivers, forces, initial assembly, stabilization, projection)."""
from __future__ import annotations

from .keys import BEAM_SECTION_SHAPES, JOINT_TYPES, STRUCTURAL_ELEMENT_TYPES, Section, _k, _req

MODEL_SECTIONS: dict[str, Section] = {
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
        _k("linear_algebra", "enum", "solver storage (auto: sparse above 100 DOFs)",
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
    "structural.damping": Section("model.damping", "Rayleigh damping α M + β K (see `corotated`).", (
        _k("rayleigh", "section", "Rayleigh coefficients", item="structural.rayleigh"),
    )),
    "structural.rayleigh": Section("model.damping.rayleigh", "Rayleigh coefficients.", (
        _k("alpha", "expr", "mass-proportional (1/s)", default=0.0),
        _k("beta", "expr", "stiffness-proportional (s)", default=0.0),
        _k("corotated", "bool", "β K of bars and co-rotational beams on their deformation rates, in the "
                                "turning element frame (false: on the total rates, β K(q = 0))", default=True),
    )),
    "structural.quantity": Section("quantity (structural)", "`{dof: NAME | [NAMES], kind}`, `{node: NAME, "
                                   "kind}` or `{element: NAME | [NAMES] | all, kind}`.", (
        _k("dof", "any", "DOF name(s)"), _k("element", "any", "element name(s) or 'all'"),
        _k("node", "name", "a node: its free translation DOFs x, y (z) (kinds displacement, velocity, "
                           "acceleration)"),
        _k("kind", "enum", "displacement | velocity | acceleration (DOFs); force | stress | strain | buckling "
                           "(elements; beams: force, stress, buckling; dampers: force)",
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
        _k("forces", "list", "force elements", item=()),   # the force laws' sections (:func:`.add_force_section`)
        _k("members", "list", "flexible structural members between node bodies (docs/flexible_members.md)",
           item=("multibody.member.bar", "multibody.member.beam")),
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
    "multibody.member.bar": Section("members[i], type: bar", "A bar between two node bodies: tension "
                                    "N = E A (L − L0)/L0 + c L̇ (engineering strain), mass ρ A L0 lumped half on "
                                    "each node.", (
        _req("type", "enum", "member type", values=("bar",)), _k("name", "name", "member name"),
        _req("nodes", "list", "[node_1, node_2]: a body (its COM) or body.marker", item="name"),
        _req("E", "expr", "Young's modulus"), _req("area", "expr", "cross-section area"),
        _k("density", "expr", "density (mass lumped on the nodes)", default=0.0),
        _k("damping", "expr", "axial dashpot c (force·time/length)", default=0.0),
        _k("initial_force", "expr", "tension N0 (force) the bar carries at the initial pose: its free length "
           "becomes L0 = Li E A/(E A + N0), Li the initial length (a pretension, or the static force of a "
           "start from equilibrium)", default=0.0),
    ), type_value="bar"),
    "multibody.member.beam": Section("members[i], type: beam", "A 3D co-rotational Euler–Bernoulli beam between two "
                                     "node frames (rigid bodies or ground markers); lumped mass and rotary "
                                     "inertia on the nodes.", (
        _req("type", "enum", "member type", values=("beam",)), _k("name", "name", "member name"),
        _req("nodes", "list", "[node_1, node_2]: a rigid body (its COM frame) or body.marker", item="name"),
        _req("E", "expr", "Young's modulus"), _req("G", "expr", "shear modulus"),
        _req("area", "expr", "cross-section area A"), _req("Iy", "expr", "second moment about local y"),
        _req("Iz", "expr", "second moment about local z"), _req("J", "expr", "torsion constant"),
        _k("density", "expr", "density (lumped mass and rotary inertia)", default=0.0),
        _k("damping", "expr", "stiffness-proportional damping β (time)", default=0.0),
        _k("orientation", "vector", "a vector in the local x–y plane, giving local y", length=3,
           default="global z; global y for a beam along z"),
    ), type_value="beam"),
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
                                    "Φ = 0 and Φ̇ = 0 (closest point in the chosen metric); the sensitivities are "
                                    "projected consistently.", (
        _k("enabled", "bool", "switch the projection on (writing the section switches it on)", default=True),
        _k("tol", "number", "bound on the last Newton correction, relative to 1 + ‖q‖", default=1e-13),
        _k("max_iterations", "integer", "iterations before the run stops with an error", default=12),
        _k("mode", "enum", "output: the run continues from the solved (index-1) state and reports the "
                           "projected one; state: it continues from the projected state", default="output",
           values=("state", "output")),
        _k("metric", "enum", "norm of the closest point: euclidean (plain 2-norm of q, q̇) or mass (the mass "
                             "matrix's norm, keeps momentum when masses differ widely; BENCHMARKS.md)",
           default="euclidean", values=("euclidean", "mass")),
    )),
    "multibody.quantity": Section("quantity (multibody)", "Exactly one of joint, body, marker, element, with `kind`.", (
        _k("joint", "name", "joint: reaction_force | reaction_force_norm | reaction_moment | "
                            "reaction_force_joint_frame | multipliers"),
        _k("body", "name", "body: position | velocity | acceleration | angle_z | angular_velocity | "
                           "angular_velocity_z"),
        _k("marker", "string", "body.marker: position | velocity"),
        _k("element", "name", "cylinder: stroke | stroke_rate | pressure_1 | pressure_2 | force | volume_1 | "
                              "volume_2; spring_damper: length | length_rate | force; member bar: force | stress | "
                              "strain | length"),
        _req("kind", "string", "what to read (by the head key, above)"),
    )),
}
