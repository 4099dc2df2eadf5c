"""One router per resource; ``app.py`` includes them with their shared dependencies."""

from . import health, metrics, solve, stream

__all__ = ["health", "metrics", "solve", "stream"]
