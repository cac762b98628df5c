"""The response types read by :mod:`dynsens.case.responses_spec`, with their key sections in
:mod:`dynsens.case_keys.general`: registered in the order of ``RESPONSE_TYPES`` (orders 10, 20, …;
a type declared in its own module takes an order between them to be listed there)."""
from __future__ import annotations

from ...case.responses_spec import READERS
from ...case_keys import AGGREGATE_TYPES
from .registry import ResponseType, register_response_type

for _i, (_type, _read) in enumerate(READERS.items()):
    register_response_type(ResponseType(_type, 10.0 * (_i + 1), _read, aggregate=_type in AGGREGATE_TYPES))
