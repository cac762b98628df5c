"""Every key a case file accepts: the one table the loaders check against and the reference and
JSON Schema are generated from (``python -m dynsens.case.schema --write``).

A :class:`Section` is one mapping of the case language (``integrator``, a response of type
``ks``, a multibody joint, ...).  Its :class:`Key` entries give the key's name, what it takes,
whether it is required, its default and a one-line meaning with units.  Sections that differ by
their ``type`` key (responses, elements, forces, time functions) are variants of a family.
This package imports nothing else from dynsens, so every loader may import it.  The table is
kept in two parts, the sections every model shares (:mod:`.general`) and those of each model
kind (:mod:`.models`), joined here in that order.
"""
from __future__ import annotations

from dataclasses import replace

from .general import GENERAL_SECTIONS
from .keys import (AGGREGATE_TYPES, BEAM_SECTION_SHAPES, JOINT_TYPES, KINDS, NO_DEFAULT,
                   RESPONSE_TYPES, STRUCTURAL_ELEMENT_TYPES, TIME_FUNCTION_TYPES, Key, Section)
from .models import MODEL_SECTIONS

SECTIONS: dict[str, Section] = {**GENERAL_SECTIONS, **MODEL_SECTIONS}


def allowed(section: str, *extra: str) -> tuple[str, ...]:
    """The keys ``section`` accepts (plus ``extra``), in table order."""
    return tuple(k.name for k in SECTIONS[section].keys) + extra


def add_element_section(name: str, section: Section) -> None:
    """Add the key section of a structural element kind that declares its keys in its own module
    (:mod:`dynsens.models.structural.elements`): the loaders check against it, the model's ``elements`` list
    names it and the generated reference lists it."""
    SECTIONS[name] = section
    model = SECTIONS["model.structural"]
    keys = tuple(replace(k, item=tuple(dict.fromkeys([*k.item, name]))) if k.name == "elements"
                 and isinstance(k.item, tuple) else k for k in model.keys)
    SECTIONS["model.structural"] = replace(model, keys=keys)


def add_force_section(name: str, section: Section, force_sections: list[str]) -> None:
    """Add the key section of a multibody force law that declares its keys in its own module
    (:mod:`dynsens.models.multibody.laws`); the model's ``forces`` list names ``force_sections``
    (every registered law's section, in the laws' order)."""
    SECTIONS[name] = section
    model = SECTIONS["model.multibody"]
    keys = tuple(replace(k, item=tuple(force_sections)) if k.name == "forces" else k for k in model.keys)
    SECTIONS["model.multibody"] = replace(model, keys=keys)


def add_response_section(type_name: str, section: Section, types: tuple[str, ...]) -> None:
    """Add the key section ``response.<type_name>`` of a response type that declares its keys in its
    own module (:mod:`dynsens.responses.types`), placed after the section of the type before it in
    ``types`` (all response types, in order); the ``type`` enum of every response section and the
    item list of ``case.responses`` become ``types``."""
    name = f"response.{type_name}"
    before = types[:types.index(type_name)]
    anchor = next((f"response.{t}" for t in reversed(before) if f"response.{t}" in SECTIONS), None)
    entries = [(k, v) for k, v in SECTIONS.items() if k != name]
    at = next((i + 1 for i, (k, _) in enumerate(entries) if k == anchor), len(entries))
    entries.insert(at, (name, section))
    SECTIONS.clear()
    for key, sec in entries:
        if key.startswith("response."):
            sec = replace(sec, keys=tuple(replace(k, values=types) if k.name == "type" else k for k in sec.keys))
        elif key == "case":
            sec = replace(sec, keys=tuple(replace(k, item=tuple(f"response.{t}" for t in types))
                                          if k.name == "responses" else k for k in sec.keys))
        SECTIONS[key] = sec


def required(section: str) -> tuple[str, ...]:
    """The keys ``section`` requires."""
    return tuple(k.name for k in SECTIONS[section].keys if k.required)


__all__ = ["AGGREGATE_TYPES", "BEAM_SECTION_SHAPES", "JOINT_TYPES", "KINDS", "NO_DEFAULT",
           "RESPONSE_TYPES", "SECTIONS", "STRUCTURAL_ELEMENT_TYPES", "TIME_FUNCTION_TYPES", "Key", "Section",
           "add_element_section", "add_force_section", "add_response_section", "allowed", "required"]
