"""The package version, in one place (read by the CLI, the reports and ``pincal.__version__``)."""

__all__ = ["__version__"]

__version__ = "0.1.0"
