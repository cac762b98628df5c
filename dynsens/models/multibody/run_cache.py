"""The multibody model's caches, declared in one place with the rule that drops each entry.

A :class:`.model.MultibodyModel` keeps what it derives during a run in one :class:`RunCache`
(``model.cache``); no other module keeps state on the model.  What is derived from one
parameter set lives with the set (:class:`.bodies.ParamsCache`, :class:`.kernel.KParamsCache`);
the kinematics by state in :class:`.kernel_compiled.KinCache` (``model._kin``).

The entries rely on the invariants of the model contract (:mod:`dynsens.models.base`): state
arrays are never changed in place (a new state is a new array), and a parameter set keeps its
identity and its values for the run.  Entries keyed by identity keep the keyed objects alive,
so an identity cannot be reused by a new object while its entry exists.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..base import Linearization, StepState
    from .assembly import InitialConditions
    from .bodies import MBParams
    from .kernel import KParams
    from .reaction_split import MinimumNormSplit
    from .redundancy import DroppedEquations
    from .residual import Evaluation
    from .sparse import SparseStructure

Array = np.ndarray


@dataclass
class RunCache:
    """What a multibody model keeps between calls; one entry per field, each replaced (never
    grown) by the call that forms it.

    Per run (keyed; replaced when the key changes):

    initial : ``(params, assembly)``, the assembly of :meth:`~.model.MultibodyModel.initial_state`
        for the parameter set ``params`` (identity); read by the initial guess and the initial
        gradient for the same set, replaced by the next assembly.
    evaluation : ``(key, evaluation, (λ, p, ṗ))``, the last residual evaluation; reused for the
        same kinematics object, time and the same λ, p, ṗ arrays (identity), or equal ones
        (``key``: id of the kinematics, t and the bytes and dtypes of λ, p, ṗ); replaced by the
        next evaluation at another state.
    linearization : ``(evaluation, linearization)``, the linearization of the evaluation object
        (identity); replaced by the next linearization of another evaluation.
    stacked : ``(params_list, kernel parameters)``, the stacked kernel parameters of the last
        list of parameter sets (identity of the list, which the entry keeps alive); replaced
        for another list.
    constraint_levels : ``(t, q, q̇, params, (Φ, Φ̇, Φ̈))``, the constraint levels (n_eq, 3) of the
        last state checked (:meth:`~.model.MultibodyModel.constraint_residuals`); reused for the
        same q, q̇ arrays and parameter set (identity) at the same t, or at any t when no
        constraint depends on time; replaced at the next state.
    solved : ``(t, projected, solved)``, the last projection of an accepted step
        (:meth:`~.model.MultibodyModel.project`): the state Newton solved and the projected one,
        for the ``*_solved`` monitors of that step (matched by t and the projected q array's
        identity); replaced at the next projection.

    Per model (built on first use from the model's fixed structure; never dropped):

    sparse : the positions of the sparse linearization's entries (:mod:`.sparse`).
    dropped : the kernel of the redundant equations left out of Φ (:mod:`.redundancy`).
    reaction_split : the minimum-norm split of dependent joints' reactions (:mod:`.reaction_split`).
    """

    initial: tuple[MBParams, InitialConditions] | None = None
    evaluation: tuple[tuple[Any, ...], Evaluation, tuple[Array, Array, Array]] | None = None
    linearization: tuple[Evaluation, Linearization] | None = None
    stacked: tuple[list[MBParams], KParams] | None = None
    constraint_levels: tuple[float, Array, Array, MBParams, Array] | None = None
    solved: tuple[float, StepState, StepState] | None = None
    sparse: SparseStructure | None = None
    dropped: DroppedEquations | None = None
    reaction_split: MinimumNormSplit | None = None
