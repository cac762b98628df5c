"""Derivative modes: they consume the primal stepper's step records.

``direct`` carries the sensitivities forward with the steps (cost grows with the number of
design variables); ``adjoint`` sweeps back over the records once per group of responses (cost
grows with the number of responses).
"""
