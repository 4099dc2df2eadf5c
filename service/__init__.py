"""skyfix: lost-in-space star identification.

``service.core`` is the pure engine (numpy, scipy, OpenCV); ``service.api`` is the thin
FastAPI layer over it; ``service.cli`` is the ``skyfix`` command.
"""

__version__ = "0.1.0"
