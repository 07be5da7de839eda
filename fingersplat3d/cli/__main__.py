"""``python -m fingersplat3d.cli``: the same as ``fs3d``."""
import sys

from .main import main

sys.exit(main())
