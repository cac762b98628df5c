"""Analyses of a model beside the transient: natural modes and linear buckling (:mod:`.modes`)."""
