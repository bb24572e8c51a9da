"""Closing the loop: which effect the calibrated model lacks, found in its residuals,
adopted or refused, with plots.

Imports the fit and below; never the study, the report or the CLI.
"""
