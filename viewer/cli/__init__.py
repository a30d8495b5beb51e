"""The command line: ``glassray [view|render|check|bench|stress] ...`` (the top floor)."""

from .commands import build_parser, main

__all__ = ["build_parser", "main"]
