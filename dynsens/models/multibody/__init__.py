"""Rigid 3D multibody models (``model.type: multibody``).

Modules: :mod:`.rotations` (Euler parameters, batched vector algebra), :mod:`.bodies`
(coordinates, inertia, kinematic vector terms), :mod:`.joints` (constraint equations),
:mod:`.forces` (gravity, point forces, torques, spring-dampers), :mod:`.hydraulics`
(two-chamber cylinder with pressure states), :mod:`.assembly` (consistent initial
conditions and their design derivatives), :mod:`.outputs` (quantities for responses),
:mod:`.spec` / :mod:`.build` (reading the case), :mod:`.model` (the residual).
"""
from .build import build_multibody  # noqa: F401  (registers "multibody")
from .model import MultibodyModel  # noqa: F401
