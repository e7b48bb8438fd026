"""Plane-strain MPM continuum reference (being built)."""
