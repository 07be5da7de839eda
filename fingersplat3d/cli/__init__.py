"""``fs3d``: one module per command (``fingersplat3d/cli/<command>.py``), assembled by ``cli.main``."""
from .main import build_parser, main

__all__ = ["main", "build_parser"]
