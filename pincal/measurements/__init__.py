"""Measurements in: joint readings with what the sensor saw, in memory and as CSV v1 files.

The bottom layer beside :mod:`pincal.robots`: imports only :mod:`pincal.errors`.
"""
