"""Option types shared by several sub-commands."""

from __future__ import annotations

from enum import StrEnum


class Lookup(StrEnum):
    """Projector pattern lookup of the renderer.

    ``nearest``: sharp DMD pixels (a staircase of about 0.15-0.2 projector px RMS in decoded
    coordinates when a camera pixel is smaller than a projector pixel on the object);
    ``bilinear``: each DMD pixel blurred over about one pixel, as by a projector lens that
    just resolves its pixels.
    """

    nearest = "nearest"
    bilinear = "bilinear"


LOOKUP_HELP = "Pattern lookup: nearest (sharp DMD pixels) or bilinear (pixels blurred by ~1 px)."
