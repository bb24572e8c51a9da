"""Robots described by Denavit–Hartenberg tables: the tables and the one DH row → joint
origin core of both conventions (``table.py``), DH-described robots (``robot.py``) and their
table files (``files.py``), the DH parameters as the unknowns of a calibration
(``parameters.py``), the DH↔URDF adapter (``urdf.py``) and ``pincal urdf-from-dh`` (``conversion.py``).

Part of :mod:`pincal.model`: imports the rest of the model, :mod:`pincal.measurements` and below.
"""
