"""Structural element kinds as registered classes behind one protocol (:mod:`.kind`).

One module per kind; every module here is imported by :func:`load_kinds` and registers its
kinds.  A structural model (:mod:`dynsens.models.structural.model`) loops over the element sets
of these kinds and names none of them.
"""
from __future__ import annotations

from .kind import (KINDS, ElementKind, ModelContext, ReadContext, element_types, kind_class, load_kinds,
                   register_kind)

__all__ = ["KINDS", "ElementKind", "ModelContext", "ReadContext", "element_types", "kind_class", "load_kinds",
           "register_kind"]
