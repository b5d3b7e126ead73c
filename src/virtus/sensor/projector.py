"""The projector between a pattern and its light: intensity response, black level, pixel
shape and lens blur, brightness fall-off.

A pattern sequence says what the projector is *told* to show (8-bit values per projector
pixel, :mod:`virtus.patterns`). A :class:`ProjectorModel` says what light comes out:

1. **Pre-compensation** (optional): the values sent are ``quantise(g^-1(p))`` for the ideal
   pattern ``p``, so that a known response ``g`` is undone before 8-bit quantisation, as
   labs do to fight gamma.
2. **Response**: ``r = black + (1 - black) g(p)`` with ``g(p) = p**gamma`` or a measured
   lookup table over the 256 input levels, and ``black = 1 / contrast_ratio``.
3. **Pixel model** (:class:`Lookup`): how the light of projector pixel ``j`` spreads along the
   pattern axis: ``nearest`` (sharp square DMD pixels), ``bilinear`` (linear interpolation
   between pixel centres) or ``psf``: a square aperture of ``fill_factor`` of the pitch
   convolved with a Gaussian lens point-spread function of ``psf_sigma_px`` (projector px);
   ``psf`` with fill factor 1 and sigma 0 is ``nearest``. The emitted profile is tabulated at
   :data:`PSF_SUPERSAMPLING` points per projector pixel and read by linear interpolation.
4. **Fall-off**: ``cos4`` multiplies the light toward direction ``theta_p`` from the
   projector axis by ``cos(theta_p)**4`` (natural vignetting of the projection lens),
   ``cos`` by ``cos(theta_p)**k`` with ``k = falloff_exponent`` (a real lens and light
   engine, fitted by ``twin --fit``).

Ideal values (gamma 1, infinite contrast, ``nearest``, no fall-off) reproduce the ideal
projector exactly.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import as_member
from virtus.errors import InputError
from virtus.io.safeio import check_keys
from virtus.sensor.camera import cos_exponent, cos_power

#: Pattern input levels of an 8-bit projector.
LEVELS = 255
#: Samples per projector pixel of the tabulated emitted profile (``psf`` pixel model): the
#: linear read-out of a profile blurred by >= 0.25 px is then accurate to ~1e-3 of its range.
PSF_SUPERSAMPLING = 8
#: Fall-off models (``cos``: ``cos(theta_p)**falloff_exponent``).
FALLOFFS = ("none", "cos4", "cos")


class Lookup(StrEnum):
    """Projector pixel model: how a pattern is read at a projector coordinate.

    ``nearest``: sharp DMD pixels, the value of the pixel containing the coordinate (a
    staircase of about 0.15-0.2 projector px RMS in decoded coordinates where a camera pixel
    is smaller than a projector pixel on the object); ``bilinear``: linear interpolation
    between pixel centres, as a projector lens that blurs each pixel over about one pixel;
    ``psf``: a fill-factor aperture convolved with a Gaussian lens PSF
    (:class:`ProjectorModel`).
    """

    nearest = "nearest"
    bilinear = "bilinear"
    psf = "psf"


def as_lookup(value: object) -> Lookup:
    """``value`` as a :class:`Lookup`, or :class:`InputError` naming ``lookup``."""
    return as_member(Lookup, "lookup", value)


def _real(value: object) -> float | None:
    """``value`` as a float when it is a finite real number (not a bool or a string)."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        return None
    try:
        number = float(value)
    except OverflowError:  # an int beyond float64
        return None
    return number if np.isfinite(number) else None


def _number(name: str, value: object, low: float, high: float, *, open_low: bool = False) -> float:
    interval = f"{'(' if open_low else '['}{low}, {high}]"
    number = _real(value)
    if number is None:
        raise InputError(name, f"a finite number in {interval}", value)
    if number < low or number > high or (open_low and number == low):
        raise InputError(name, f"a number in {interval}", value)
    return number


def _response_lut(value: object) -> tuple[float, ...]:
    """A measured response table as 256 floats, or :class:`InputError` naming
    ``response_lut`` and the entry at fault."""
    expected = f"a list of {LEVELS + 1} non-decreasing numbers in [0, 1] ending at 1"
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, list | tuple):
        raise InputError("response_lut", expected, value)
    if len(value) != LEVELS + 1:
        raise InputError("response_lut", expected, f"{len(value)} values")
    table: list[float] = []
    for index, item in enumerate(value):
        number = _real(item)
        if number is None or not 0.0 <= number <= 1.0:
            raise InputError("response_lut", "finite numbers in [0, 1]", f"index {index}: {item}")
        if table and number < table[-1]:
            got = f"index {index}: {item} after {table[-1]}"
            raise InputError("response_lut", "non-decreasing numbers", got)
        table.append(number)
    if abs(table[-1] - 1.0) > 1e-9:
        raise InputError("response_lut", "1 as the light of level 255", f"index 255: {value[-1]}")
    return tuple(table)


@dataclass(frozen=True)
class ProjectorModel:
    """What light a projector emits for a pattern (see the module docstring).

    Parameters
    ----------
    pixel : pixel model (:class:`Lookup`).
    gamma : power-law response exponent (> 0; 1 = linear); ignored with ``response_lut``.
    response_lut : measured response: 256 non-decreasing outputs in [0, 1] for the input
        levels 0..255 (output of level 255 = 1).
    precompensate : send ``g^-1`` of the ideal pattern (then quantise), undoing the response.
    contrast_ratio : full-on / full-off light (e.g. 1000 for 1000:1); None = infinite.
    fill_factor : lit fraction of the pixel pitch along the pattern axis (``psf``), (0, 1].
    psf_sigma_px : Gaussian lens blur, projector px (``psf``), >= 0.
    falloff : ``"none"``, ``"cos4"`` or ``"cos"`` (``cos(theta_p)**falloff_exponent``).
    falloff_exponent : ``k`` of a ``"cos"`` fall-off, in (0, 32]; None otherwise.
    name : preset name, for reports.
    """

    pixel: Lookup = Lookup.nearest
    gamma: float = 1.0
    response_lut: tuple[float, ...] | None = None
    precompensate: bool = False
    contrast_ratio: float | None = None
    fill_factor: float = 1.0
    psf_sigma_px: float = 0.0
    falloff: str = "none"
    falloff_exponent: float | None = None
    name: str = "custom"

    def __post_init__(self) -> None:
        object.__setattr__(self, "pixel", as_lookup(self.pixel))
        object.__setattr__(self, "gamma", _number("gamma", self.gamma, 0.0, 10.0, open_low=True))
        if self.response_lut is not None:
            object.__setattr__(self, "response_lut", _response_lut(self.response_lut))
        if not isinstance(self.precompensate, bool):
            raise InputError("precompensate", "true or false", self.precompensate)
        if self.contrast_ratio is not None:
            ratio = _number("contrast_ratio", self.contrast_ratio, 1.0, 1e12, open_low=True)
            object.__setattr__(self, "contrast_ratio", ratio)
        fill = _number("fill_factor", self.fill_factor, 0.0, 1.0, open_low=True)
        object.__setattr__(self, "fill_factor", fill)
        sigma = _number("psf_sigma_px", self.psf_sigma_px, 0.0, 100.0)
        object.__setattr__(self, "psf_sigma_px", sigma)
        if self.pixel != Lookup.psf and (fill != 1.0 or sigma != 0.0):
            raise InputError("pixel", '"psf" for a fill factor or a PSF width', self.pixel.value)
        if self.falloff not in FALLOFFS:
            raise InputError("falloff", f"one of {FALLOFFS}", self.falloff)
        exponent = cos_exponent("falloff", self.falloff, self.falloff_exponent)
        object.__setattr__(self, "falloff_exponent", exponent)
        if not isinstance(self.name, str) or not self.name:
            raise InputError("name", "a non-empty string", self.name)

    def with_(self, **changes: Any) -> ProjectorModel:
        """A copy with some parameters replaced (checked again)."""
        return replace(self, **changes)

    @property
    def black(self) -> float:
        """Relative light of a full-off pixel, ``1 / contrast_ratio`` (0 if infinite)."""
        return 0.0 if self.contrast_ratio is None else 1.0 / self.contrast_ratio

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters."""
        data = asdict(self)
        data["pixel"] = self.pixel.value
        data["response_lut"] = None if self.response_lut is None else list(self.response_lut)
        if data["falloff_exponent"] is None:  # only "cos" has one; older files lack it
            del data["falloff_exponent"]
        return data

    @classmethod
    def from_dict(cls, data: object) -> ProjectorModel:
        """Inverse of :meth:`to_dict` (also a projector file's content); unknown keys refused."""
        check_keys(data, sorted(cls.__dataclass_fields__), "projector")
        return cls(**dict(data))  # type: ignore[call-overload]

    # --- the response -------------------------------------------------------------------

    def response(self, levels: np.ndarray) -> np.ndarray:
        """``g``: relative light (0..1, before the black level) for pattern values in [0, 1]."""
        values = np.clip(np.asarray(levels, dtype=np.float64), 0.0, 1.0)
        if self.response_lut is not None:
            return np.interp(values * LEVELS, np.arange(LEVELS + 1), self.response_lut)
        return values**self.gamma

    def inverse_response(self, light: np.ndarray) -> np.ndarray:
        """``g^-1``: the pattern value in [0, 1] that gives relative light ``light``."""
        values = np.clip(np.asarray(light, dtype=np.float64), 0.0, 1.0)
        if self.response_lut is not None:
            lut = np.asarray(self.response_lut)
            # The first level reaching each light value (the table may be flat at the ends).
            unique, first = np.unique(lut, return_index=True)
            return np.interp(values, unique, first / LEVELS)
        return values ** (1.0 / self.gamma)

    def emitted_profile(self, sequence: Any, index: int) -> np.ndarray:
        """(L,) float64 light of frame ``index`` per projector pixel along its axis, relative to
        a full-on pixel (``L = 1`` for uniform frames): pre-compensation, 8-bit quantisation,
        response and black level."""
        frame = sequence.frames[index]
        if self.precompensate:
            length = 1 if frame.uniform else sequence.span(frame.direction)
            scale = 1.0 if frame.uniform else sequence.axis_scale(frame.direction)
            ideal = frame.values(np.arange(length, dtype=np.float64), scale)
            sent = np.rint(self.inverse_response(ideal) * LEVELS) / LEVELS
        else:
            sent = np.asarray(sequence.profile(index), dtype=np.float64)
        return self.black + (1.0 - self.black) * self.response(sent)

    # --- the pixel model ----------------------------------------------------------------

    @property
    def supersampling(self) -> int:
        """Table points per projector pixel of :meth:`spread` (1 unless ``psf``)."""
        return PSF_SUPERSAMPLING if self.pixel == Lookup.psf else 1

    def spread(self, profiles: np.ndarray) -> np.ndarray:
        """The ``psf`` pixel model on (L, F) per-pixel light: (L * R, F) tabulated light at
        ``R = supersampling`` points per pixel, point ``k`` at projector coordinate
        ``(k + 0.5) / R - 0.5`` (read it with :meth:`table_coordinate`). Other pixel models
        return ``profiles`` unchanged."""
        if self.pixel != Lookup.psf:
            return profiles
        from scipy.ndimage import gaussian_filter1d

        r = PSF_SUPERSAMPLING
        offsets = (np.arange(r) + 0.5) / r - 0.5  # within the pixel, px from its centre
        # Each table point's share of the lit aperture [-f/2, f/2] (area-weighted), with the
        # light of the pixel spread over its aperture: a pixel's power is kept.
        half = 0.5 * self.fill_factor
        low, high = offsets - 0.5 / r, offsets + 0.5 / r
        cover = np.clip(np.minimum(high, half) - np.maximum(low, -half), 0.0, None) * r
        table = (profiles[:, None, :] * (cover / self.fill_factor)[None, :, None]).reshape(
            -1, profiles.shape[1]
        )
        if self.psf_sigma_px > 0:
            table = gaussian_filter1d(
                table, self.psf_sigma_px * r, axis=0, mode="constant", truncate=5.0
            )
        return table

    def table_coordinate(self, coordinate: np.ndarray) -> np.ndarray:
        """Projector coordinates (px) -> positions in the table of :meth:`spread`."""
        r = self.supersampling
        # Python floats keep float32 arrays float32 and work on device arrays too.
        return coordinate * float(r) + (r - 1) / 2

    @property
    def falloff_power(self) -> float:
        """The exponent ``k`` of the fall-off ``cos(theta_p)**k`` (0 without, 4 for ``cos4``)."""
        return cos_power(self.falloff, self.falloff_exponent)

    def falloff_factor(
        self, u_p: np.ndarray, v_p: np.ndarray, intrinsics: Any
    ) -> np.ndarray | None:
        """``cos(theta_p)**k`` at projector pixels (float32, same shape; k = 4 for ``cos4``),
        or None without fall-off; ``intrinsics``: the projector's (its fx, fy, cx, cy)."""
        if self.falloff == "none":
            return None
        # Python floats: float32 arrays stay float32, and device (Dr.Jit) arrays work too.
        x = (u_p - float(intrinsics.cx)) / float(intrinsics.fx)
        y = (v_p - float(intrinsics.cy)) / float(intrinsics.fy)
        cos2 = 1.0 / (1.0 + x * x + y * y)
        # Plain arithmetic (``**`` with a Python float) so Dr.Jit arrays take the same path.
        factor = cos2 * cos2 if self.falloff == "cos4" else cos2 ** (0.5 * self.falloff_power)
        return factor.astype(np.float32) if isinstance(factor, np.ndarray) else factor


#: Named projectors for ``--projector NAME``. ``ideal``: sharp DMD pixels, linear response,
#: infinite contrast (today's renderer); ``paper``: what the paper's renderer models (a
#: textured rectangle light: linear, bilinear texture filtering, no black level);
#: ``lightcrafter``: a DLP LightCrafter 4500-class projector as labs run it -- gamma 2.2
#: pre-compensated, 1000:1 contrast, 92 % fill factor, a lens blur of 0.5 px, cos^4 fall-off
#: (representative values, not one unit's measurement).
PROJECTOR_PRESETS: dict[str, ProjectorModel] = {
    "ideal": ProjectorModel(name="ideal"),
    "paper": ProjectorModel(name="paper", pixel=Lookup.bilinear),
    "lightcrafter": ProjectorModel(
        name="lightcrafter",
        pixel=Lookup.psf,
        gamma=2.2,
        precompensate=True,
        contrast_ratio=1000.0,
        fill_factor=0.92,
        psf_sigma_px=0.5,
        falloff="cos4",
    ),
}


def load_projector(spec: str | Path) -> ProjectorModel:
    """A projector model by preset name (:data:`PROJECTOR_PRESETS`) or from a YAML/JSON file
    of :class:`ProjectorModel` parameters (unknown keys refused)."""
    from virtus.io.safeio import read_yaml

    if isinstance(spec, str) and spec in PROJECTOR_PRESETS:
        return PROJECTOR_PRESETS[spec]
    path = Path(spec)
    if not path.is_file():
        raise InputError(
            "projector",
            f"a preset name ({', '.join(PROJECTOR_PRESETS)}) or a projector file",
            str(spec),
        )
    data = read_yaml(path, "projector file", expect=dict)
    return ProjectorModel.from_dict({"name": path.stem, **data})
