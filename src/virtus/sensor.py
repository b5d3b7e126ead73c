"""The sensor models of a scan: the projector's pixel model and the camera's response.

Camera: radiance -> exposure -> (noise) -> digital numbers (8, 10, 12 or 16 bit).

* Exposure: ``DN = round(exposure * L + noise)``, saturating at full scale
  ``2**bit_depth - 1`` (saturation is the sensor's physics, not a silent clamp). ``"auto"``
  exposure scales the radiance of a full-on (white) projector frame so that its
  ``auto_percentile``-th percentile over the pixels that receive light reaches
  ``auto_target`` of full scale.
* Noise: additive Gaussian read noise of ``read_noise_dn`` digital numbers (standard
  deviation, before quantisation). The full EMVA 1288 model builds on the same streams.

Randomness is counter-based: the noise of pixel ``p`` in frame ``f`` is element
``p mod NOISE_BLOCK_PIXELS`` of a block of standard normals drawn from a Philox generator
keyed by ``(seed, f, p // NOISE_BLOCK_PIXELS)``. A frame's noise therefore depends only on
the seed, the frame index and the pixel, never on how the work is split into blocks or
threads, or on the backend that computed the radiance: the same seed gives the same bytes.

Frames of 10, 12 and 16 bits are stored as uint16, 8-bit frames as uint8.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from enum import StrEnum
from types import ModuleType
from typing import Any, Literal

import numpy as np

from virtus.checks import positive
from virtus.errors import InputError, VirtusError

#: Camera ADC bit depths.
BIT_DEPTHS = (8, 10, 12, 16)
#: Pixels per counter-based noise block (part of the noise stream's definition: changing it
#: changes the bytes of every noisy capture).
NOISE_BLOCK_PIXELS = 1 << 14
#: Largest seed (seeds are non-negative 63-bit integers, so they survive JSON and C longs).
MAX_SEED = (1 << 63) - 1
#: Description of the noise stream, recorded with every capture.
NOISE_STREAM = f"philox4x64(SeedSequence([seed, frame, pixel // {NOISE_BLOCK_PIXELS}]))"


class Lookup(StrEnum):
    """Projector pixel model: how a pattern is read at a projector coordinate.

    ``nearest``: sharp DMD pixels, the value of the pixel containing the coordinate (a
    staircase of about 0.15-0.2 projector px RMS in decoded coordinates where a camera pixel
    is smaller than a projector pixel on the object); ``bilinear``: linear interpolation
    between pixel centres, as a projector lens that blurs each pixel over about one pixel.
    """

    nearest = "nearest"
    bilinear = "bilinear"


def as_lookup(value: object) -> Lookup:
    """``value`` as a :class:`Lookup`, or :class:`InputError` naming ``lookup``."""
    try:
        return Lookup(value)
    except ValueError:
        raise InputError("lookup", f"one of {[m.value for m in Lookup]}", value) from None


def as_seed(rng: np.random.Generator | int | None) -> int:
    """The integer seed of the counter-based streams from the project's ``rng`` argument.

    An int is used as it is (``0 <= seed <= MAX_SEED``); ``None`` is seed 0 (captures are
    reproducible by default); a Generator draws one seed, so a seeded Generator still gives
    reproducible captures.
    """
    if isinstance(rng, np.random.Generator):
        return int(rng.integers(0, MAX_SEED, endpoint=True))
    if rng is None:
        return 0
    if isinstance(rng, bool) or not isinstance(rng, int | np.integer):
        raise InputError("seed", "a non-negative integer, a numpy Generator or None", rng)
    if not 0 <= int(rng) <= MAX_SEED:
        raise InputError("seed", f"an integer in 0..{MAX_SEED}", rng)
    return int(rng)


def noise_block(seed: int, frame: int, block: int) -> np.ndarray:
    """(NOISE_BLOCK_PIXELS,) float32 standard normals of one counter-based block."""
    generator = np.random.Generator(np.random.Philox(np.random.SeedSequence([seed, frame, block])))
    return generator.standard_normal(NOISE_BLOCK_PIXELS, dtype=np.float32)


def standard_normal(seed: int, frame: int, pixels: slice) -> np.ndarray:
    """(stop - start,) float32 standard normals of frame ``frame`` at the row-major pixel
    indices ``pixels`` (a slice with step 1), identical however the pixels are split."""
    start, stop = pixels.start or 0, pixels.stop
    first, last = start // NOISE_BLOCK_PIXELS, (stop - 1) // NOISE_BLOCK_PIXELS
    values = np.concatenate([noise_block(seed, frame, b) for b in range(first, last + 1)])
    offset = start - first * NOISE_BLOCK_PIXELS
    return values[offset : offset + stop - start]


@dataclass(frozen=True)
class Sensor:
    """The camera: linear response, exposure, read noise and quantisation.

    Parameters
    ----------
    bit_depth : ADC bits: 8 (uint8 frames), 10, 12 or 16 (uint16 frames).
    exposure : digital numbers per unit radiance (> 0), or ``"auto"``.
    auto_percentile : percentile (0-100] of the white frame used by auto-exposure.
    auto_target : fraction (0-1] of full scale that this percentile is mapped to.
    read_noise_dn : standard deviation of additive Gaussian noise, DN (>= 0; 0 = noise-free).
    """

    bit_depth: int = 8
    exposure: float | Literal["auto"] = "auto"
    auto_percentile: float = 99.0
    auto_target: float = 0.9
    read_noise_dn: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.bit_depth, bool) or self.bit_depth not in BIT_DEPTHS:
            raise InputError("bit_depth", f"one of {BIT_DEPTHS}", self.bit_depth)
        if self.exposure != "auto":
            object.__setattr__(self, "exposure", positive("exposure", self.exposure))
        if not 0 < self.auto_percentile <= 100:
            raise InputError("auto_percentile", "a percentile in (0, 100]", self.auto_percentile)
        if not 0 < self.auto_target <= 1:
            raise InputError("auto_target", "a fraction in (0, 1]", self.auto_target)
        noise = self.read_noise_dn
        if isinstance(noise, bool) or not isinstance(noise, int | float) or not noise >= 0:
            raise InputError("read_noise_dn", "a finite number >= 0 (DN)", noise)
        if not np.isfinite(noise):
            raise InputError("read_noise_dn", "a finite number >= 0 (DN)", noise)
        object.__setattr__(self, "read_noise_dn", float(noise))

    @property
    def full_scale(self) -> int:
        """Largest digital number, ``2**bit_depth - 1``."""
        return (1 << self.bit_depth) - 1

    @property
    def dtype(self) -> type[np.unsignedinteger]:
        """numpy dtype of the frames."""
        return np.uint8 if self.bit_depth == 8 else np.uint16

    @property
    def noisy(self) -> bool:
        """True when digitisation draws random numbers."""
        return self.read_noise_dn > 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (the capture's ``sensor`` entry)."""
        data: dict[str, Any] = asdict(self)
        data["noise_stream"] = NOISE_STREAM
        return data

    @classmethod
    def from_dict(cls, data: object) -> Sensor:
        """Inverse of :meth:`to_dict`; unknown keys are refused."""
        if not isinstance(data, dict):
            raise InputError("sensor", "a mapping of sensor parameters", data)
        fields = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - fields - {"noise_stream"})
        if unknown:
            raise InputError("sensor", f"keys among {sorted(fields)}", unknown)
        stream = data.get("noise_stream", NOISE_STREAM)
        if stream != NOISE_STREAM:
            raise InputError("sensor.noise_stream", NOISE_STREAM, stream)
        return cls(**{key: data[key] for key in fields if key in data})

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
        *,
        seed: int = 0,
        frames: np.ndarray | None = None,
        pixels: slice | None = None,
    ) -> np.ndarray:
        """Digital numbers of a block of frames.

        Parameters
        ----------
        radiance : (F, n) float32 radiance of frames ``frames`` at the row-major pixel
            indices ``pixels`` (or any shape when the sensor is noise-free).
        exposure : digital numbers per unit radiance.
        seed : seed of the counter-based noise streams.
        frames : (F,) int frame indices in the sequence (needed with noise).
        pixels : slice of row-major pixel indices, step 1 (needed with noise).

        Returns
        -------
        Same shape as ``radiance``, uint8 or uint16.
        """
        values = np.multiply(radiance, np.float32(exposure), dtype=np.float32)
        if self.noisy:
            if frames is None or pixels is None or values.ndim != 2:
                raise InputError(
                    "digitize", "(F, n) radiance with frames and pixels for a noisy sensor",
                    f"shape {values.shape}",
                )  # fmt: skip
            sigma = np.float32(self.read_noise_dn)
            for row, frame in enumerate(np.asarray(frames).reshape(-1)):
                values[row] += sigma * standard_normal(seed, int(frame), pixels)
        # rint rounds half to even; values above full scale saturate, below zero clip.
        np.rint(values, out=values)
        np.clip(values, 0, self.full_scale, out=values)
        return values.astype(self.dtype)

    def digitize_jit(self, radiance: Any, exposure: float, dr: ModuleType) -> Any:
        """:meth:`digitize` of a noise-free sensor on a Dr.Jit Float array (on the device
        that traced it); returns a Float of whole digital numbers in [0, full scale]."""
        if self.noisy:
            raise VirtusError("digitize_jit: noisy sensors digitise on the host streams")
        return dr.clip(dr.round(radiance * float(exposure)), 0.0, float(self.full_scale))
