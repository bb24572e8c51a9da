"""REPORT.json: what a calibration or diagnosis reports, written and read back.

Imports everything below it; only the CLI imports it.
"""
