"""Response types, one registered :class:`ResponseType` per case ``type`` (see :mod:`.registry`)."""
from .registry import (RESPONSE_REGISTRY, ResponseType, load_response_types, register_response_type,
                       response_type_names)

__all__ = ["RESPONSE_REGISTRY", "ResponseType", "load_response_types", "register_response_type",
           "response_type_names"]
