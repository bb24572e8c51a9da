"""The paper's pipeline, Franaszek & Marvel (2022): circle point analysis (``cpa.py``),
Methods 1–3 (``methods.py``), the maximum-likelihood estimator (``ml_estimator.py``) and the
linearised noise limit of them all (``noise_limit.py``).

Built on the generic fit (:mod:`pincal.fit`: solver, registrations), the residuals, the paper's
simulated experiment (:mod:`pincal.simulation.paper`) and the model; used by the study, the report
and the CLI.
"""
