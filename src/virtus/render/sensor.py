"""Camera sensor stage: radiance -> exposure -> digital numbers (8 or 16 bit).

The stage is pointwise and noise-free for now; it takes an ``rng`` so that noise (shot,
read, quantisation dither), gamma and other effects can be added here without changing
callers, with per-sample determinism.

Exposure: ``DN = round(exposure * L)``, saturating at full scale ``2**bit_depth - 1``
(saturation is the sensor's physics, not a silent clamp). ``"auto"`` exposure scales the
radiance of a full-on (white) projector frame so that its ``auto_percentile``-th percentile
over the pixels that receive light reaches ``auto_target`` of full scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType
from typing import Any, Literal

import numpy as np

from virtus.checks import as_rng, positive
from virtus.errors import InputError, VirtusError

BIT_DEPTHS = (8, 16)


@dataclass(frozen=True)
class Sensor:
    """Linear camera response with exposure and quantisation.

    Parameters
    ----------
    bit_depth : 8 (uint8 frames) or 16 (uint16 frames).
    exposure : digital numbers per unit radiance (> 0), or ``"auto"``.
    auto_percentile : percentile (0-100] of the white frame used by auto-exposure.
    auto_target : fraction (0-1] of full scale that this percentile is mapped to.
    """

    bit_depth: int = 8
    exposure: float | Literal["auto"] = "auto"
    auto_percentile: float = 99.0
    auto_target: float = 0.9

    def __post_init__(self) -> None:
        if self.bit_depth not in BIT_DEPTHS:
            raise InputError("bit_depth", "8 or 16", self.bit_depth)
        if self.exposure != "auto":
            object.__setattr__(self, "exposure", positive("exposure", self.exposure))
        if not 0 < self.auto_percentile <= 100:
            raise InputError("auto_percentile", "a percentile in (0, 100]", self.auto_percentile)
        if not 0 < self.auto_target <= 1:
            raise InputError("auto_target", "a fraction in (0, 1]", self.auto_target)

    @property
    def full_scale(self) -> int:
        """Largest digital number, ``2**bit_depth - 1``."""
        return (1 << self.bit_depth) - 1

    @property
    def dtype(self) -> type[np.unsignedinteger]:
        """numpy dtype of the frames."""
        return np.uint8 if self.bit_depth == 8 else np.uint16

    def exposure_for(self, white: np.ndarray) -> float:
        """Digital numbers per unit radiance for this sensor.

        Parameters
        ----------
        white : (H, W) float radiance under a full-on projector (ambient included).
        """
        if self.exposure != "auto":
            return float(self.exposure)
        lit = white[white > 0]
        if lit.size == 0:
            raise VirtusError(
                "auto exposure: no pixel receives light (is the projector aimed at the scene?)"
            )
        level = float(np.percentile(lit, self.auto_percentile))
        return self.auto_target * self.full_scale / level

    def digitize(
        self,
        radiance: np.ndarray,
        exposure: float,
        rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        """Pointwise response of a block: radiance (any shape, float32) -> digital numbers
        (same shape, uint8/uint16). ``rng`` is for noise models (unused: noise-free)."""
        values = np.multiply(radiance, np.float32(exposure), dtype=np.float32)
        # rint rounds half to even; values above full scale saturate.
        np.rint(values, out=values)
        np.clip(values, 0, self.full_scale, out=values)
        return values.astype(self.dtype)

    def digitize_jit(self, radiance: Any, exposure: float, dr: ModuleType) -> Any:
        """:meth:`digitize` on a Dr.Jit Float array (on the device that traced it); returns a
        Float of whole digital numbers in [0, full scale]."""
        return dr.clip(dr.round(radiance * float(exposure)), 0.0, float(self.full_scale))

    def capture(
        self,
        radiance: np.ndarray,
        exposure: float,
        rng: np.random.Generator | int | None = None,
    ) -> np.ndarray:
        """Digital frames from radiance.

        Parameters
        ----------
        radiance : (..., H, W) float32 radiance (e.g. (F, H, W) frames).
        exposure : digital numbers per unit radiance (see :meth:`exposure_for`).
        rng : randomness for noise models (unused by this noise-free sensor).

        Returns
        -------
        Frames of the same shape, uint8 or uint16.
        """
        generator = as_rng(rng)
        exposure = positive("exposure", exposure)
        out = np.empty(radiance.shape, dtype=self.dtype)
        flat_in, flat_out = radiance.reshape(-1), out.reshape(-1)
        block = 1 << 18  # elements per block: stays in cache
        for start in range(0, flat_in.size, block):
            flat_out[start : start + block] = self.digitize(
                flat_in[start : start + block], exposure, generator
            )
        return out
