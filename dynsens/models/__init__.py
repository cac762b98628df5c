"""Governing equations (building block 1 of the paper): models that expose a residual."""
