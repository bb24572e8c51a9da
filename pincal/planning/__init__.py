"""Measurement planning: which robot configurations to measure, how many, in which order (``pincal plan``)."""
