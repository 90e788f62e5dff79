"""rfw: a frame-graph framework for real-time graphics research."""

__version__ = "0.1.0"
