"""The thin FastAPI layer over ``service.core``: ``create_app(settings)``, ``Settings``."""

from .app import create_app
from .settings import Settings, get_settings

__all__ = ["Settings", "create_app", "get_settings"]
