"""The package's version, one place for the CLI, the wheel and the benchmark's records."""

__version__ = "0.1.0"
