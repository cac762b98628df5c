"""Time integration (building block 2 of the paper)."""
from .newmark import Newmark, make_scheme

__all__ = ["Newmark", "make_scheme"]
