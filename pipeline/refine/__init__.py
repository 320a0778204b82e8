"""Refinement: one fit of the whole kinematic chain to all measurements of a session (issue 15)."""
