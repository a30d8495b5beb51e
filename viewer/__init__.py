"""glassray: a real-time Whitted ray tracer for a rod in a glass of liquid."""

from .base.version import __version__

__all__ = ["__version__"]
