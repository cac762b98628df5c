"""An axial element whose law the compiled kernel does not know is refused when the kernel
layout is built, never evaluated with another element's law."""
from __future__ import annotations

import copy

import pytest

import dynsens
from conftest import CASES
from dynsens.models.multibody.forces import SpringDamper
from dynsens.models.multibody.kernel import Layout


def test_unknown_axial_law_is_an_error():
    case = dynsens.load_case(CASES / "four_bar.yaml")
    m = case.model
    spring = next(f for f in m.forces if isinstance(f, SpringDamper))
    odd = copy.copy(spring)
    odd.law_kind = 7
    with pytest.raises(TypeError) as exc:
        Layout(len(m.bodies), m.eqs, [odd], [])
    assert "'spring' declares law_kind 7" in str(exc.value)
    none = copy.copy(spring)
    none.law_kind = None                       # no compiled law: the numpy kernel evaluates it
    assert Layout(len(m.bodies), m.eqs, [none], []).compiled_laws is False
    assert Layout(len(m.bodies), m.eqs, [spring], []).compiled_laws is True
