r"""The protocol every multibody force law follows, and the registry of laws by the ``type`` of a
``forces[i]`` entry.

A :class:`ForceLaw` reads the case entries of one force ``type`` into force elements
(:class:`.forces.ForceElement`) and resolves their outputs.  The multibody builder, the key table
and the output resolver know no force type by name: :func:`.build_forces.read_forces` reads each
entry with the law its ``type`` selects, and :func:`.outputs.resolve_output` asks the laws for
their elements' quantities.  A law declares

* its case keys, a :class:`~dynsens.case_keys.Section` (:attr:`ForceLaw.keys`), which
  :func:`register_law` adds to the key table (the loaders check against it, the generated
  reference lists it);
* :meth:`ForceLaw.read`: one entry into the element(s) it creates, with their range checks at
  reading (problems collected with their YAML paths);
* :meth:`ForceLaw.elements` and :meth:`ForceLaw.output`: its elements in a built model and their
  outputs (:attr:`ForceLaw.output_kinds`);
* :attr:`ForceLaw.compiled`: whether the compiled kernels serve its elements.

The element carries the evaluation: its generalized force ``add(ctx, out)`` (and, when
``closed_form``, ``add_batch`` / ``add_jacobian``), as the model already calls every force
element.  The built-in laws keep their existing paths: spring-dampers and hydraulic cylinders are
axial elements with a law in the compiled kernels (``law_kind``), rotational spring-dampers have
their own blocks.  A new law declares ``compiled = False``; its elements are then the model's
*other forces* (:func:`.residual.other_forces_q`): their state Jacobians are exact for
closed-form elements, by complex step otherwise, their design partials by the complex step of
the residual, and a step with them runs the Python path.

Every module of :mod:`dynsens.models.multibody.laws` is imported by :func:`load_laws`: a new law
is a new module there, nothing else.
"""
from __future__ import annotations

import importlib
import pkgutil
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from ...case_keys import Section, add_force_section
from ...errors import ProblemCollector
from .._keys import did_you_mean

if TYPE_CHECKING:
    from ..base import Output
    from .model import MultibodyModel
    from .spec import Reader


@dataclass
class ForceElements:
    """Where the force elements read go: ``forces`` (the model's force list: point forces,
    torques, rotational spring-dampers and every law without a list of its own), ``cylinders``,
    ``springs``; ``n_p`` the first-order (pressure) states of the cylinders so far."""

    forces: list
    cylinders: list
    springs: list
    n_p: int = 0


class ForceLaw(ABC):
    """The force elements of one ``type``.  Subclasses set :attr:`type`, :attr:`order` and
    :attr:`keys`, read entries, and name their elements and outputs."""

    type: ClassVar[str]
    #: place among the laws (lower first): in the list of known types and the key table
    order: ClassVar[float]
    keys: ClassVar[Section]
    #: the compiled kernels serve the law's elements (built-in laws only; a new law runs in Python):
    #: declared by every law in its own class body, True or False; :func:`register_law` refuses a
    #: law that declares neither
    compiled: ClassVar[bool]
    #: the ``kind`` values of its elements' outputs (none: the elements have no outputs)
    output_kinds: ClassVar[tuple[str, ...]] = ()
    #: what the elements are called in messages
    what: ClassVar[str] = "force"

    @property
    def section(self) -> str:
        """The name of its key section in the table."""
        return f"multibody.{self.type}"

    @abstractmethod
    def read(self, rd: "Reader", entry: dict, path: str, name: str, out: ForceElements) -> None:
        """Read one ``forces[i]`` entry at YAML ``path`` (its keys checked already) into ``out``;
        problems go to ``rd.problems``."""

    def elements(self, model: "MultibodyModel") -> list[Any]:
        """Its elements in a built model (those with outputs)."""
        return []

    def output(self, model: "MultibodyModel", element: Any, kind: Any, path: str,
               problems: ProblemCollector) -> "Output | None":
        """The quantity ``kind`` of ``element`` (problems at ``path``)."""
        problems.add(f"{path}.kind", f"a {self.what} has no outputs")
        return None

    def known_kind(self, kind: Any, path: str, problems: ProblemCollector, listed: bool = True) -> bool:
        """Whether ``kind`` is one of :attr:`output_kinds`; otherwise reports it at ``path.kind``."""
        if kind in self.output_kinds:
            return True
        known = f" (known: {', '.join(self.output_kinds)})" if listed else ""
        problems.add(f"{path}.kind", f"unknown {self.what} quantity {kind!r}"
                                     f"{did_you_mean(kind, self.output_kinds)}{known}")
        return False


FORCE_LAWS: dict[str, ForceLaw] = {}


@dataclass
class _Registry:
    loaded: bool = False      # every module of .laws imported


_STATE = _Registry()


def register_law(cls: type[ForceLaw]) -> type[ForceLaw]:
    """Class decorator: register a force law under its ``type``, and its key section in the
    case's key table.  Raises TypeError for a law that does not declare ``compiled`` itself."""
    if not isinstance(cls.__dict__.get("compiled"), bool):
        raise TypeError(f"force law {cls.__name__} ({cls.type!r}) must declare `compiled = True` (the compiled "
                        "kernels serve it) or `compiled = False` (Python only) in its class body")
    FORCE_LAWS[cls.type] = cls()
    add_force_section(f"multibody.{cls.type}", cls.keys,
                      [f"multibody.{t}" for t in sorted(FORCE_LAWS, key=lambda t: FORCE_LAWS[t].order)])
    return cls


def load_laws() -> dict[str, ForceLaw]:
    """Import every module of :mod:`.laws` (each registers its laws) and return the registry,
    ordered by the laws' :attr:`ForceLaw.order`."""
    if not _STATE.loaded:
        from . import laws
        for info in pkgutil.iter_modules(laws.__path__):
            importlib.import_module(f"{laws.__name__}.{info.name}")
        _STATE.loaded = True
    return dict(sorted(FORCE_LAWS.items(), key=lambda kv: kv[1].order))


def force_types() -> list[str]:
    """The registered force types, in the laws' order."""
    return list(load_laws())
