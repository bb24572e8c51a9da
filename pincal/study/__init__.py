"""The paper's simulation study (Sections 7–9): protocol, tasks, executors, tables,
findings, files and figures.

Imports the paper's pipeline, the fit and below; never diagnosis, the report or the CLI.
"""
