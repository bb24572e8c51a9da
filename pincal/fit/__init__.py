"""The fit: solver, registrations, CPA, identifiability, outliers, the paper's three
methods, the maximum-likelihood estimator, any-chain calibration, the linearised
noise limit and the error metrics of eq 24.

Imports residuals, simulation, the model and below.
"""
