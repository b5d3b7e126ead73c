"""virtus: a virtual fringe projection profilometry (FPP) sensor.

Conventions (see README "Conventions"):

* Units are SI inside (metres, radians); human-facing metrics carry the unit in their name.
* Camera and projector frames follow OpenCV: x right, y down, z forward.
* Pixel (col=0, row=0) has its centre at (u, v) = (0.0, 0.0); arrays are ``[row, col]``.
* Transforms are named by frames: ``proj2cam`` maps projector-frame points into the camera
  frame, ``X_cam = R @ X_proj + t``.
"""

from virtus.errors import InputError, VirtusError

__version__ = "0.1.0"
__all__ = ["InputError", "VirtusError", "__version__"]
