r"""The protocol every structural element kind follows, and the registry of kinds by the case's
element ``type``.

An :class:`ElementKind` holds *all* elements of one kind in a model (a set, evaluated together
as arrays).  The structural model (:class:`~dynsens.models.structural.model.StructuralModel`) knows
no kind by name: it reads each ``elements[i]`` entry into the set its ``type`` selects, and then
loops over its sets, in the fixed order of their :attr:`ElementKind.order` (sums are formed in
that order, which keeps every result bit for bit), for

* the parameters a design makes of the set (:meth:`ElementKind.parameters`) and its lumped mass;
* its contribution to the residual, f_int (:meth:`ElementKind.internal_force`) and, for
  dampers, the velocity forces (:meth:`ElementKind.damping_force`);
* its state Jacobians as (rows, cols, values) triplets: ∂f_int/∂q
  (:meth:`ElementKind.tangent`), its constant damping (:meth:`ElementKind.damping_entries`)
  and ∂f/∂q̇ (:meth:`ElementKind.damping_tangent`);
* the residual rows each of its parameters reaches (:meth:`ElementKind.design_touch`);
* its outputs (:meth:`ElementKind.output`), its range checks (:meth:`ElementKind.range_problem`);
* and whether a compiled step serves it (:attr:`ElementKind.compiled`: declared by the kind).

A kind declares its case keys as a :class:`~dynsens.case_keys.Section` (:attr:`ElementKind.keys`)
or names a section of the key table (:attr:`ElementKind.section`); :func:`register_kind`
adds a declared section to the table, so that the loaders check against it and the generated
reference (``python -m dynsens.case.schema --write``) lists it.  Every module of this package is
imported by :func:`load_kinds`: a new kind is a new module here, nothing else.
"""
from __future__ import annotations

import importlib
import pkgutil
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar

import numpy as np

from ....case_keys import Section, add_element_section
from ....errors import ProblemCollector
from ...parameters import ParameterTable
from ...sparse_assembly import RightProduct

Triplets = tuple[Any, Any, Any]       # (rows, cols, values): entries of an (n, n) matrix
Touch = tuple[Any, Any]               # (parameter indices, DOF indices) of one element


def extend(v: np.ndarray) -> np.ndarray:
    """v (..., n) with a trailing zero entry: the slot of fixed DOFs and ground."""
    return np.concatenate([v, np.zeros(v.shape[:-1] + (1,), dtype=v.dtype)], axis=-1)


@dataclass
class ReadContext:
    """What reading an element entry needs from the model being built: the node and DOF names,
    the parameter table and the problem list.  DOF index n is the slot of fixed DOFs and ground."""

    dim: int
    table: ParameterTable
    problems: ProblemCollector
    node_coords: dict[str, list[int]]
    dof: Callable[[Any, str], int]               # a DOF name -> its index
    node_dofs: Callable[[Any, str], list[int]]   # a node -> its translation DOFs
    beam_dofs: Callable[[Any, str], list[int]]   # a node -> its translations and rotations
    given_coords: dict[str, Any] = field(default_factory=dict)   # the nodes' ``coords`` entries

    @property
    def n(self) -> int:
        """Number of free DOFs (the index of the fixed slot)."""
        return self.dof("ground", "")


@dataclass
class ModelContext:
    """What a set needs of the built model to evaluate: its DOF count, dimension and the scatter
    of element values onto nodal forces (:meth:`StructuralModel._scatter`)."""

    n: int
    dim: int
    scatter: Callable[[np.ndarray, np.ndarray, bool], RightProduct]
    linear: bool          # the model is linear (springs use their linear law alone)


class ElementKind(ABC):
    """All elements of one kind in a structural model.  Subclasses set :attr:`type` (the case's
    element ``type``), :attr:`order` (their place in every sum) and their keys; they override
    the contributions they have (the defaults contribute nothing)."""

    type: ClassVar[str]
    #: the model dimensions the kind serves (a ``type`` may have one kind per dimension)
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    #: place in every sum over the kinds (lower first); the built-in kinds keep today's order
    order: ClassVar[float]
    #: the key section's name in the table, and the section itself if the kind declares it
    section: ClassVar[str]
    keys: ClassVar[Section | None] = None
    #: a compiled step serves models of this kind (:func:`dynsens.models.structural.step.serves`):
    #: every kind declares it in its own class body, True or False (Python only); a kind that
    #: declares neither is refused at registration (no default decides it silently)
    compiled: ClassVar[bool]
    #: what the elements' outputs report (``kind`` of an output quantity), and in which unit
    output_kinds: ClassVar[tuple[str, ...]] = ()
    #: the elements that ``element: all`` names (members: bars and beams)
    member: ClassVar[bool] = False

    def __init__(self) -> None:
        self.names: list[str] = []

    def __len__(self) -> int:
        return len(self.names)

    # ------------------------------------------------------------------ reading
    @abstractmethod
    def read(self, entry: dict, path: str, name: str, ctx: ReadContext) -> None:
        """Read one case entry at YAML ``path`` (problems go to ``ctx.problems``)."""

    def freeze(self, model: ModelContext) -> None:  # noqa: B027 (a kind without arrays has nothing to do)
        """Index arrays and scatter maps, once all entries are read."""

    def dofs(self) -> list[int]:
        """The DOFs the elements give mass to (a DOF without mass is refused)."""
        return []

    # ------------------------------------------------------------------ traits
    def served_compiled(self) -> bool:
        """Whether a compiled step serves these elements (their :attr:`compiled` declaration,
        refined by what the elements read, e.g. dampers: the linear ones only)."""
        return self.compiled or not len(self)

    def nonlinear(self) -> bool:
        """Whether f_int or the damping forces depend nonlinearly on the state."""
        return False

    def damped(self) -> bool:
        """Whether the elements add damping (velocity forces)."""
        return False

    # ------------------------------------------------------------------ parameters
    #: derived parameter keys that :meth:`parameters` writes and the batched outputs stack
    stack_keys: ClassVar[tuple[str, ...]] = ()

    def parameters(self, pv: np.ndarray, out: dict[str, Any], mass: np.ndarray) -> None:  # noqa: B027
        """Derived element data for the parameter vector ``pv`` into ``out``; lumped masses
        added into ``mass`` (n + 1: the last slot is dropped)."""

    def structural_mass(self, params: dict[str, Any]) -> Any:
        """The elements' own mass (mass unit), or None when they have none."""
        return None

    # ------------------------------------------------------------------ residual and Jacobians
    def internal_force(self, q: np.ndarray, params: dict[str, Any]) -> np.ndarray | None:
        """Nodal internal forces (..., n) at q (..., n); params may carry a leading batch axis."""
        return None

    def tangent(self, q: np.ndarray, params: dict[str, Any], corotated: bool) -> list[Triplets]:
        """∂f_int/∂q as triplets at one state; without ``corotated`` only the part that does not
        turn with the elements (the K₀ of Rayleigh damping that is not co-rotated)."""
        return []

    def damping_entries(self, params: dict[str, Any]) -> list[Triplets]:
        """The constant (linear viscous) damping matrix's entries."""
        return []

    def damping_force(self, qd: np.ndarray, params: dict[str, Any]) -> Any:
        """Nonlinear velocity forces (..., n), or None."""
        return None

    def damping_tangent(self, qd: np.ndarray, params: dict[str, Any]) -> list[Triplets]:
        """∂(:meth:`damping_force`)/∂q̇ as triplets at one state."""
        return []

    # ------------------------------------------------------------------ inertia
    def mass_turns(self) -> bool:
        """Whether the elements have a mass M(q) that turns with them (inertia forces per element)."""
        return False

    def constant_mass(self) -> bool:
        """Whether the elements have a constant non-diagonal (consistent) mass matrix."""
        return False

    def inertia_force(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]) -> Any:
        """Nodal inertia forces (..., n) beyond the lumped masses' (extended states), or None."""
        return None

    def mass_entries(self, qe: np.ndarray, params: dict[str, Any]) -> list[Triplets]:
        """The non-diagonal mass matrix's entries at the extended state qe."""
        return []

    def inertia_jacobians(self, qe: np.ndarray, qde: np.ndarray, qdde: np.ndarray, params: dict[str, Any]) -> Any:
        """(rows, cols, ∂/∂q̈, ∂/∂q̇, ∂/∂q values) of a turning mass's inertia forces, or None."""
        return None

    def damped_kind(self) -> Any:
        """The elements' share of Rayleigh's β K on their deformation rates (a
        :class:`~dynsens.models.structural.corotated_damping.DampedKind`), or None where K₀ keeps them."""
        return None

    def design_touch(self) -> list[Touch]:
        """Per element: the parameter indices it reads and the DOFs (residual rows) it reaches."""
        return []

    # ------------------------------------------------------------------ outputs and checks
    def output(self, index: np.ndarray, kind: str, path: str, problems: ProblemCollector
               ) -> tuple[Callable[..., np.ndarray], tuple[str, ...]] | None:
        """The function (t, s, params) -> values (..., m) of quantity ``kind`` of the elements
        ``index`` and its m labels; None with a problem listed when it cannot be formed."""
        return None

    def output_reads(self, index: np.ndarray, kind: str) -> list[Touch] | None:
        """Per row of the output ``kind`` of the elements ``index`` (in its order): the parameter
        indices and the DOFs of q it reads, a superset (the adjoint colours its probes by it);
        None where the kind does not declare them (the adjoint then finds them by probing)."""
        return None

    def refusal(self, kind: str) -> str:
        """Why an output ``kind`` the elements do not report is refused."""
        return f"{self.type} elements report {', '.join(repr(k) for k in self.output_kinds)}"

    def range_problem(self, qe: np.ndarray, params: dict[str, Any]) -> str | None:
        """Why the state qe (n + 1) has left the elements' range of validity, or None."""
        return None


# ---------------------------------------------------------------------- the registry
KINDS: dict[str, list[type[ElementKind]]] = {}


def register_kind(cls: type[ElementKind]) -> type[ElementKind]:
    """Class decorator: register an element kind under its ``type`` (one class per dimension),
    and its key section (when it declares one) in the case's key table.  Raises TypeError for a
    kind that does not declare ``compiled`` itself (compiled, or Python only)."""
    if not isinstance(cls.__dict__.get("compiled"), bool):
        raise TypeError(f"element kind {cls.__name__} ({cls.type!r}) must declare `compiled = True` (a compiled "
                        "step serves it) or `compiled = False` (Python only) in its class body")
    KINDS.setdefault(cls.type, []).append(cls)
    if cls.keys is not None:
        add_element_section(cls.section, cls.keys)
    return cls


def load_kinds() -> dict[str, list[type[ElementKind]]]:
    """Import every module of this package (each registers its kinds) and return the registry."""
    from .. import elements
    for info in pkgutil.iter_modules(elements.__path__):
        importlib.import_module(f"{elements.__name__}.{info.name}")
    return KINDS


def kind_class(type_name: Any, dim: int) -> type[ElementKind] | None:
    """The kind that reads elements of ``type_name`` in a model of dimension ``dim``."""
    for cls in load_kinds().get(type_name, []) if isinstance(type_name, str) else []:
        if dim in cls.dims:
            return cls
    return None


def element_types() -> list[str]:
    """The registered element types, in the order of their kinds."""
    kinds = sorted((c for cs in load_kinds().values() for c in cs), key=lambda c: c.order)
    return list(dict.fromkeys(c.type for c in kinds))
