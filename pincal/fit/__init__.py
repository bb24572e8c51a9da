"""The fit of any chain: solver, registrations, identifiability, how many parameters to keep,
outliers, one calibration pipeline for sensor and socket-fixture rows, several sessions, the
level the data support, the MAP fit with priors, plausibility and the error metrics of eq 24.
The paper's own pipeline (CPA, Methods 1–3, the ML estimator, the noise limit) is
:mod:`pincal.paper`, built on this one.

Imports residuals, simulation, the model and below.
"""
