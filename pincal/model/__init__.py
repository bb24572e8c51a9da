"""The robot model: URDF in and out, DH-described robots (``dh/``), the Pinocchio chain, the
parameterisations of its joint placements (DH, offsets, full), their analytic
sensitivities, the effect catalogue (joint shifts and sensor terms), the sensor's
registration and the corrected-URDF writer.

Imports :mod:`pincal.measurements.csv_v1`, :mod:`pincal.robots` and :mod:`pincal.errors` only.
"""
