"""fingersplat3d: contactless fingerprint 3D reconstruction from 2-3 uncalibrated photos."""
from .errors import FS3DError, InputError
from .scene import Camera, Capture, View, look_at

__version__ = "0.1.0"
__all__ = ["Camera", "Capture", "View", "look_at", "FS3DError", "InputError", "__version__"]
