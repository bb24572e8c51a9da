"""Simulated measurements: the paper's KUKA experiment (Section 7) and any chain,
through the same sensor model the fit uses.

Imports the model and below.
"""
