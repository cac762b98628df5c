"""Nonlinear solver (building block 3 of the paper): Newton-Raphson and linear algebra."""
