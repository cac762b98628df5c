"""Structural element kinds as registered classes behind one protocol (:mod:`.kind`).

A package of its own, not ``models/structural/``: the module :mod:`dynsens.models.structural`
keeps its name (its public import path), and the kinds are meant for any model that carries
structural members (flexible members in mechanisms follow).  One module per kind; every module
here is imported by :func:`load_kinds` and registers its kinds.
"""
from __future__ import annotations

from .kind import (KINDS, ElementKind, ModelContext, ReadContext, element_types, kind_class, load_kinds,
                   register_kind)

__all__ = ["KINDS", "ElementKind", "ModelContext", "ReadContext", "element_types", "kind_class", "load_kinds",
           "register_kind"]
