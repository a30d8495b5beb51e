"""glassray: a real-time Whitted ray tracer for a rod in a glass of liquid."""

__version__ = "0.1.0"
