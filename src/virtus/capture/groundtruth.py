"""Per-pixel ground truth of one rendered pose (camera frame, metres, projector pixels)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from virtus.checks import positive
from virtus.errors import InputError

#: Names of the arrays :meth:`GroundTruth.arrays` returns (the capture ``gt/`` files).
ARRAY_NAMES = (
    "depth",
    "points",
    "normals",
    "proj_uv",
    "mask",
    "mask_hit",
    "mask_shadow",
    "mask_outside",
    "mask_multibounce",
    "mask_saturated",
)
#: Arrays that captures written before they existed lack; :meth:`GroundTruth.from_arrays`
#: gives them their defaults.
OPTIONAL_ARRAY_NAMES = ("mask_multibounce", "mask_saturated")


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Exact geometry seen through each camera pixel centre (not averaged over supersamples).

    Attributes
    ----------
    depth : (H, W) float64, metres: z of the surface point along the camera axis; NaN where
        the ray hits nothing.
    points : (H, W, 3) float64, metres, camera frame; NaN where nothing is hit.
    normals : (H, W, 3) float64 unit surface normals, camera frame, turned toward the camera;
        NaN where nothing is hit.
    proj_uv : (H, W, 2) float64 projector pixel coordinates ``(u_p, v_p)`` of the surface
        point (pixel-centre convention, projector distortion applied); finite wherever the
        point is in front of the projector, even if shadowed or outside the projector image.
    mask_hit : (H, W) bool, the pixel-centre ray hits a surface.
    mask_shadow : (H, W) bool, hit but the projector's centre is occluded from the point.
    mask_outside : (H, W) bool, hit but outside the projector image
        (``u_p`` not in [-0.5, W_p - 0.5) or ``v_p`` not in [-0.5, H_p - 0.5), or behind it).
    mask_multibounce : (H, W) bool, the pixel's white-projector radiance from interreflections
        (light paths with one or more bounces before the camera's surface point) exceeds the
        direct one: a decoded phase there is dominated by indirect light. All False for a
        single-bounce render, and the default (captures written before it existed).
    mask_saturated : (H, W) bool, the pixel reached the camera's full scale (ADC or full
        well) in at least one frame; its phase is clipped. All False by default.
    """

    depth: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    proj_uv: np.ndarray
    mask_hit: np.ndarray
    mask_shadow: np.ndarray
    mask_outside: np.ndarray
    mask_multibounce: np.ndarray | None = None
    mask_saturated: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in OPTIONAL_ARRAY_NAMES:
            value = getattr(self, name)
            if value is None:
                object.__setattr__(self, name, np.zeros_like(self.mask_hit, dtype=bool))
            elif np.shape(value) != np.shape(self.mask_hit):
                raise InputError(
                    name, f"shape {np.shape(self.mask_hit)} (the camera image)", np.shape(value)
                )

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: hit, lit by the projector and inside its image (decodable pixels)."""
        return self.mask_hit & ~self.mask_shadow & ~self.mask_outside

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the camera image."""
        return self.depth.shape  # type: ignore[return-value]

    def phase(self, period_px: float, direction: str) -> np.ndarray:
        """Absolute phase ``2 pi u_p / T`` (``direction="v"``, vertical fringes) or
        ``2 pi v_p / T`` (``"h"``), (H, W) float64 radians; NaN outside :attr:`mask`."""
        period = positive("period_px", period_px)
        if direction not in ("v", "h"):
            raise InputError("direction", '"v" (along u_p) or "h" (along v_p)', direction)
        coordinate = self.proj_uv[..., 0 if direction == "v" else 1]
        return np.where(self.mask, 2.0 * np.pi * coordinate / period, np.nan)

    def arrays(self) -> dict[str, np.ndarray]:
        """All arrays by name (see :data:`ARRAY_NAMES`), ``mask`` included."""
        return {name: getattr(self, name) for name in ARRAY_NAMES}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> GroundTruth:
        """Inverse of :meth:`arrays` (``mask`` is recomputed, not read; the arrays of
        :data:`OPTIONAL_ARRAY_NAMES` may be absent and then get their defaults)."""
        required = [name for name in ARRAY_NAMES if name not in ("mask", *OPTIONAL_ARRAY_NAMES)]
        missing = [name for name in required if name not in arrays]
        if missing:
            raise InputError("ground truth", f"arrays {ARRAY_NAMES}", f"missing {missing}")
        present = [name for name in ARRAY_NAMES if name != "mask" and name in arrays]
        return cls(**{name: arrays[name] for name in present})
