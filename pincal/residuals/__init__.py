"""Residuals: one :class:`~pincal.residuals.base.Objective` per error function —
pairwise distances (eq 10–12), relative rotations (eq 14–17), their weighted sum
(eq 18) and the absolute sensor residual — with analytic Jacobians.

Imports the model and below.
"""
