"""Responses: their definitions, the response set of a run, sizing aggregates, final responses."""
