"""The file-level jobs a user runs — calibrate, evaluate, diagnose, plan, extract, simulate,
urdf-from-dh — each taking paths and a settings value, writing its files whole and returning what
happened as a value; nothing here prints or parses arguments (that is :mod:`pincal.cli`).

Imports the report and below.
"""
