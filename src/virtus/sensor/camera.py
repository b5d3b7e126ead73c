"""The camera: its response from radiance to digital numbers (EMVA 1288).

Camera: radiance -> exposure -> (noise) -> digital numbers (8, 10, 12 or 16 bit).

* Exposure: ``DN = round(exposure * L + noise)``, saturating at full scale
  ``2**bit_depth - 1`` (saturation is the sensor's physics, not a silent clamp). ``"auto"``
  exposure scales the radiance of a full-on (white) projector frame so that its
  ``auto_percentile``-th percentile over the pixels that receive light reaches
  ``auto_target`` of full scale.
* Noise: the EMVA 1288 linear model (:class:`Sensor`): shot noise, dark noise, dark
  current, DSNU, PRNU, full well, gain, black level, ADC; presets in :data:`SENSOR_PRESETS`
  and sensor files (:func:`load_sensor`).

Randomness comes from the counter-based streams of :mod:`virtus.sensor.noise`: a frame's
noise is a pure function of ``(seed, frame, pixel)``.

Frames of 10, 12 and 16 bits are stored as uint16, 8-bit frames as uint8.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from types import ModuleType
from typing import Any, Literal

import numpy as np

from virtus.errors import InputError, VirtusError
from virtus.io.safeio import check_keys
from virtus.sensor.noise import LEGACY_NOISE_STREAMS, NOISE_STREAM, as_seed, standard_normal

#: Camera ADC bit depths.
BIT_DEPTHS = (8, 10, 12, 16)
#: Camera vignetting models: none, ``cos(theta)**4`` (the natural fall-off of an ideal thin
#: lens), or ``cos(theta)**k`` with the exponent ``vignetting_exponent`` (a real lens: pupil
#: aberration and mechanical vignetting make k differ from 4; fitted by ``twin --fit``).
VIGNETTING = ("none", "cos4", "cos")
#: Largest exponent k of a ``cos`` vignetting or fall-off (cos(30 deg)**32 = 1e-2).
MAX_COS_EXPONENT = 32.0
#: Why an auto exposure is impossible.
NO_LIGHT = "auto exposure: no pixel receives light (is the projector aimed at the scene?)"
#: Stream "frame" indices of the fixed-pattern noise maps (beyond any real frame index):
#: the same for every capture of one sensor, as a real sensor's pattern is.
_PRNU_STREAM = 1 << 40
_DSNU_STREAM = (1 << 40) + 1


@functools.lru_cache(maxsize=4)
def _fixed_pattern(seed: int, stream: int, n_pixels: int) -> np.ndarray:
    """Read-only (n_pixels,) float32 standard normals of a fixed-pattern map, drawn once per
    sensor and image size from the counter-based stream ``(seed, stream, block)`` (so any
    prefix equals the map of a smaller image). Cached: every frame of every capture reads
    the same map."""
    values = standard_normal(seed, stream, slice(0, n_pixels))
    values.setflags(write=False)
    return values


@dataclass(frozen=True)
class Sensor:
    """The camera: exposure, the EMVA 1288 linear sensor model, and the ADC.

    With ``system_gain_dn_per_e`` None the sensor is ideal (noise-free, linear,
    ``DN = round(exposure L)``). With it, the EMVA 1288 model (parameters named as a
    datasheet names them) turns the radiance of each pixel into digital numbers:

    * signal electrons ``mu_e = exposure L (1 + PRNU_i) / K`` (the exposure is in DN per
      unit radiance, so ``exposure / (K eta)`` photons per unit radiance hit the pixel);
    * dark electrons ``mu_d = I_dark t_exp + DSNU_i``;
    * temporal noise: shot noise of signal and dark current (Poisson, drawn as a Gaussian of
      the same variance: exact in mean and variance, which is what EMVA 1288 measures) plus
      dark (read) noise ``sigma_d``;
    * the well clips at ``saturation_capacity_e`` (the dark noise of the read-out is not
      clipped at zero: the black level keeps it in range); ``DN = round(K n + black_level_dn)``,
      clipped to ``[0, 2**bit_depth - 1]``.

    So ``mu_y = K (mu_d + eta mu_p) + black`` and ``sigma_y^2 = K^2 sigma_d^2 + sigma_q^2 +
    K (mu_y - mu_y.dark)`` (EMVA 1288 release 4, the linear model; sigma_q^2 = 1/12 DN^2).
    PRNU and DSNU are per-pixel, fixed for a sensor (``fixed_pattern_seed``), the same in
    every frame and capture.

    Parameters
    ----------
    bit_depth : ADC bits: 8 (uint8 frames), 10, 12 or 16 (uint16 frames).
    exposure : digital numbers per unit radiance (> 0), or ``"auto"``.
    auto_percentile : percentile (0-100] of the white frame used by auto-exposure.
    auto_target : fraction (0-1] of full scale that this percentile is mapped to.
    quantum_efficiency : eta, electrons per photon (0-1]; sets the photon count a given
        signal needs (reported), not the signal itself.
    system_gain_dn_per_e : K, DN per electron; None = ideal noise-free sensor.
    dark_noise_e : sigma_d, temporal dark noise, electrons.
    saturation_capacity_e : full well, electrons (None: only the ADC saturates).
    dark_current_e_per_s : mean dark current, electrons per second.
    exposure_time_s : exposure time, seconds (for the dark current).
    dsnu_e : dark signal non-uniformity, standard deviation over pixels, electrons.
    prnu : photo-response non-uniformity, standard deviation of the relative gain (0.01 = 1 %).
    black_level_dn : offset added before the ADC, DN (keeps dark noise above 0).
    fixed_pattern_seed : seed of the PRNU and DSNU maps.
    vignetting : ``"none"``, ``"cos4"`` or ``"cos"``: the camera lens's fall-off
        ``cos(theta)**4`` (or ``cos(theta)**k``, ``k = vignetting_exponent``) of the angle
        between a pixel's ray and the optical axis.
    vignetting_exponent : ``k`` of ``"cos"`` vignetting, in (0, 32]; None otherwise.
    name : preset name, for reports.
    """

    bit_depth: int = 8
    exposure: float | Literal["auto"] = "auto"
    auto_percentile: float = 99.0
    auto_target: float = 0.9
    quantum_efficiency: float = 1.0
    system_gain_dn_per_e: float | None = None
    dark_noise_e: float = 0.0
    saturation_capacity_e: float | None = None
    dark_current_e_per_s: float = 0.0
    exposure_time_s: float = 0.0
    dsnu_e: float = 0.0
    prnu: float = 0.0
    black_level_dn: float = 0.0
    fixed_pattern_seed: int = 0
    vignetting: str = "none"
    vignetting_exponent: float | None = None
    name: str = "custom"

    def __post_init__(self) -> None:
        depth = self.bit_depth
        if isinstance(depth, float) and depth.is_integer():
            depth = int(depth)
        if (
            isinstance(depth, bool)
            or not isinstance(depth, int | np.integer)
            or depth not in BIT_DEPTHS
        ):
            raise InputError("bit_depth", f"one of {BIT_DEPTHS}", self.bit_depth)
        object.__setattr__(self, "bit_depth", int(depth))
        if not (isinstance(self.exposure, str) and self.exposure == "auto"):
            exposure = _real("exposure", self.exposure, '"auto" or a number > 0 (DN per radiance)')
            if exposure <= 0:
                raise InputError("exposure", '"auto" or a number > 0', self.exposure)
            object.__setattr__(self, "exposure", exposure)
        for name, low, high, what in (
            ("auto_percentile", 0.0, 100.0, "a percentile in (0, 100]"),
            ("auto_target", 0.0, 1.0, "a fraction in (0, 1]"),
            ("quantum_efficiency", 0.0, 1.0, "a fraction in (0, 1]"),
        ):
            value = _real(name, getattr(self, name), what)
            if not low < value <= high:
                raise InputError(name, what, getattr(self, name))
            object.__setattr__(self, name, value)
        for name in ("system_gain_dn_per_e", "saturation_capacity_e"):
            if getattr(self, name) is not None:
                value = _real(name, getattr(self, name), "a number > 0 or null")
                if value <= 0:
                    raise InputError(name, "a number > 0 or null", getattr(self, name))
                object.__setattr__(self, name, value)
        for name in ("dark_noise_e", "dark_current_e_per_s", "exposure_time_s", "dsnu_e",
                     "prnu", "black_level_dn"):  # fmt: skip
            object.__setattr__(self, name, _non_negative(name, getattr(self, name)))
        if self.prnu >= 1:
            raise InputError("prnu", "a relative deviation < 1", self.prnu)
        if self.black_level_dn >= self.full_scale:
            raise InputError(
                "black_level_dn", f"< full scale {self.full_scale}", self.black_level_dn
            )
        seed = self.fixed_pattern_seed
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise InputError("fixed_pattern_seed", "an integer >= 0", seed)
        try:
            object.__setattr__(self, "fixed_pattern_seed", as_seed(seed))
        except InputError as error:
            raise InputError("fixed_pattern_seed", error.expected, error.got) from None
        if self.vignetting not in VIGNETTING:
            raise InputError("vignetting", f"one of {VIGNETTING}", self.vignetting)
        object.__setattr__(
            self,
            "vignetting_exponent",
            cos_exponent("vignetting", self.vignetting, self.vignetting_exponent),
        )
        if not isinstance(self.name, str) or not self.name:
            raise InputError("name", "a non-empty string", self.name)
        noisy = any((self.dark_noise_e, self.dark_current_e_per_s * self.exposure_time_s,
                     self.dsnu_e, self.prnu, self.saturation_capacity_e))  # fmt: skip
        if noisy and self.system_gain_dn_per_e is None:
            raise InputError(
                "system_gain_dn_per_e", "a gain (DN/e-) for a sensor with noise or a full well",
                None,
            )  # fmt: skip

    def with_(self, **changes: Any) -> Sensor:
        """A copy with some parameters replaced (checked again)."""
        return replace(self, **changes)

    @property
    def full_scale(self) -> int:
        """Largest digital number, ``2**bit_depth - 1``."""
        return (1 << self.bit_depth) - 1

    @property
    def dtype(self) -> type[np.unsignedinteger]:
        """numpy dtype of the frames."""
        return np.uint8 if self.bit_depth == 8 else np.uint16

    @property
    def saturation_dn(self) -> int:
        """The digital number at and above which a pixel is saturated: the full well's
        (``K * well + black``) or the ADC's full scale, whichever is lower."""
        if self.saturation_capacity_e is None:
            return self.full_scale
        well = self.system_gain_dn_per_e * self.saturation_capacity_e + self.black_level_dn  # type: ignore[operator]
        return int(min(self.full_scale, np.floor(well)))

    @property
    def vignetting_power(self) -> float:
        """The exponent ``k`` of the vignetting ``cos(theta)**k`` (0 without, 4 for ``cos4``)."""
        return cos_power(self.vignetting, self.vignetting_exponent)

    def vignetting_gain(self, intrinsics: Any) -> np.ndarray:
        """(P,) float32 relative irradiance of each camera pixel (row-major): 1 without
        vignetting, ``cos(theta)**k`` of the pixel-centre ray otherwise (k = 4 for
        ``"cos4"``)."""
        n = intrinsics.width * intrinsics.height
        if self.vignetting == "none":
            return np.ones(n, dtype=np.float32)
        rays = intrinsics.unproject(intrinsics.pixel_grid().reshape(-1, 2))
        if self.vignetting == "cos4":
            return (rays[:, 2] ** 4).astype(np.float32)
        return (rays[:, 2] ** self.vignetting_power).astype(np.float32)

    @property
    def noisy(self) -> bool:
        """True when digitisation follows the EMVA model (draws random numbers)."""
        return self.system_gain_dn_per_e is not None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (the capture's ``sensor`` entry)."""
        data: dict[str, Any] = asdict(self)
        if data["vignetting_exponent"] is None:  # only "cos" has one; older files lack it
            del data["vignetting_exponent"]
        data["noise_stream"] = NOISE_STREAM
        return data

    @classmethod
    def from_dict(cls, data: object) -> Sensor:
        """Inverse of :meth:`to_dict` (also a sensor file's content); unknown keys are
        refused."""
        fields = set(cls.__dataclass_fields__)
        check_keys(data, sorted(fields | {"noise_stream"}), "sensor")
        stream = data.get("noise_stream", NOISE_STREAM)  # type: ignore[union-attr]
        if stream != NOISE_STREAM and stream not in LEGACY_NOISE_STREAMS:
            raise InputError("sensor.noise_stream", NOISE_STREAM, stream)
        return cls(**{key: data[key] for key in fields if key in data})  # type: ignore[index]

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
            raise VirtusError(NO_LIGHT)
        return self.exposure_for_level(float(np.percentile(lit, self.auto_percentile)))

    def exposure_for_level(self, level: float) -> float:
        """The auto exposure that maps a white-frame radiance ``level`` (its
        ``auto_percentile``-th percentile over lit pixels) to ``auto_target`` of full scale."""
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
            indices ``pixels`` (or any shape when the sensor is ideal).
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
            values = self._electrons_to_dn(values, seed, np.asarray(frames).reshape(-1), pixels)
        # rint rounds half to even; values above full scale saturate, below zero clip.
        np.rint(values, out=values)
        np.clip(values, 0, self.full_scale, out=values)
        return values.astype(self.dtype)

    def _electrons_to_dn(
        self, signal_dn: np.ndarray, seed: int, frames: np.ndarray, pixels: slice
    ) -> np.ndarray:
        """EMVA model of a (F, n) block whose noise-free signal is ``signal_dn`` (DN)."""
        normal = np.stack([standard_normal(seed, int(frame), pixels) for frame in frames])
        prnu = dsnu = None
        if self.prnu:
            prnu = _fixed_pattern(self.fixed_pattern_seed, _PRNU_STREAM, pixels.stop)[pixels]
        if self.dsnu_e:
            dsnu = _fixed_pattern(self.fixed_pattern_seed, _DSNU_STREAM, pixels.stop)[pixels]
        return self.emva(signal_dn, normal, prnu, dsnu, np)

    def fixed_patterns(self, n_pixels: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The (n_pixels,) float32 standard normals of the PRNU and DSNU maps (None where the
        sensor has no such non-uniformity): the same for every frame and capture."""
        prnu = (
            _fixed_pattern(self.fixed_pattern_seed, _PRNU_STREAM, n_pixels) if self.prnu else None
        )
        dsnu = (
            _fixed_pattern(self.fixed_pattern_seed, _DSNU_STREAM, n_pixels) if self.dsnu_e else None
        )
        return prnu, dsnu

    def emva(self, signal_dn: Any, normal: Any, prnu: Any, dsnu: Any, xp: ModuleType) -> Any:
        """The EMVA 1288 linear model on noise-free signals (DN), before rounding.

        The one definition of the model, for numpy arrays on the host and Dr.Jit arrays on
        the device: only arithmetic and ``xp.sqrt``, ``xp.maximum``, ``xp.minimum``.

        Parameters
        ----------
        signal_dn : exposure times radiance, DN (float32 array).
        normal : standard normals of the temporal noise, broadcastable to ``signal_dn``.
        prnu, dsnu : standard normals of the fixed-pattern maps at the same pixels, or None.
        xp : ``numpy`` or ``drjit``.

        Returns
        -------
        Digital numbers before rounding and clipping (float32, same shape).
        """
        gain = float(self.system_gain_dn_per_e)  # type: ignore[arg-type]
        scale = 1.0 / gain
        if prnu is not None:
            scale = scale * (1.0 + float(self.prnu) * prnu)
        electrons = signal_dn * scale
        dark_current = float(self.dark_current_e_per_s * self.exposure_time_s)
        # Temporal noise: shot noise of signal and dark current, and the dark (read) noise.
        variance = xp.maximum(electrons, 0.0) + (dark_current + float(self.dark_noise_e) ** 2)
        electrons = electrons + xp.sqrt(variance) * normal + dark_current
        if dsnu is not None:
            electrons = electrons + float(self.dsnu_e) * dsnu
        if self.saturation_capacity_e is not None:
            # Only the top is clipped: the dark (read) noise is added after the well, and
            # the black level keeps it above zero DN.
            electrons = xp.minimum(electrons, float(self.saturation_capacity_e))
        return electrons * gain + float(self.black_level_dn)

    def digitize_jit(
        self, radiance: Any, exposure: float, dr: ModuleType, noise: Any = None
    ) -> Any:
        """:meth:`digitize` on a Dr.Jit Float array (on the device that traced it): whole
        digital numbers in [0, full scale] as a Float. A noisy sensor needs ``noise``, a tuple
        ``(normal, prnu, dsnu)`` of Dr.Jit arrays of the same streams the host draws."""
        values = radiance * float(exposure)
        if self.noisy:
            if noise is None:
                raise VirtusError("digitize_jit: a noisy sensor needs its noise streams")
            values = self.emva(values, *noise, dr)
        return dr.clip(dr.round(values), 0.0, float(self.full_scale))


def _real(name: str, value: object, expected: str) -> float:
    """``value`` as a float when it is a finite real number (an int or a float, not a bool,
    a string or a list), else :class:`InputError` naming ``name`` and ``expected``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(name, expected, value)
    try:
        number = float(value)
    except OverflowError:  # an int beyond float64
        raise InputError(name, f"{expected} (finite)", value) from None
    if not np.isfinite(number):
        raise InputError(name, f"{expected} (finite)", value)
    return number


def cos_exponent(name: str, model: str, exponent: object) -> float | None:
    """Check the exponent of a ``cos`` fall-off model (camera vignetting or projector
    fall-off, ``name``): a number in (0, :data:`MAX_COS_EXPONENT`] with ``"cos"``, None
    (not given) with the other models."""
    key = f"{name}_exponent"
    if model != "cos":
        if exponent is not None:
            raise InputError(key, f'null unless {name} is "cos" (it is "{model}")', exponent)
        return None
    value = _real(key, exponent, f'a number in (0, {MAX_COS_EXPONENT:g}] for {name} "cos"')
    if not 0.0 < value <= MAX_COS_EXPONENT:
        raise InputError(key, f"a number in (0, {MAX_COS_EXPONENT:g}]", exponent)
    return value


def cos_power(model: str, exponent: float | None) -> float:
    """The exponent ``k`` of a fall-off model: 0 for ``none``, 4 for ``cos4``, else its own."""
    return {"none": 0.0, "cos4": 4.0}.get(model, exponent)  # type: ignore[return-value]


def _non_negative(name: str, value: object) -> float:
    number = _real(name, value, "a finite number >= 0")
    if number < 0:
        raise InputError(name, "a finite number >= 0", value)
    return number


#: Named sensors for ``--sensor NAME``. ``ideal`` and ``paper`` are noise-free 8-bit sensors
#: (the paper's renderer models no sensor effect); ``imx174`` is a 12-bit machine-vision
#: camera with the published EMVA 1288 figures of the Sony IMX174 (eta 77 % at 525 nm,
#: sigma_d 6.8 e-, full well 32,691 e-; gain set so the full well fills the 12-bit range;
#: PRNU 0.5 %, DSNU 1 e-, typical of its datasheets); ``webcam`` is an 8-bit consumer-class
#: CMOS sensor with representative, not one datasheet's, values (small 6,000 e- well, 12 e-
#: dark noise, 1.5 % PRNU, 4 e- DSNU, 50 e-/s dark current at 33 ms).
SENSOR_PRESETS: dict[str, Sensor] = {
    "ideal": Sensor(name="ideal"),
    "paper": Sensor(name="paper"),
    "imx174": Sensor(
        name="imx174",
        bit_depth=12,
        quantum_efficiency=0.77,
        system_gain_dn_per_e=4095 / 32691,
        dark_noise_e=6.8,
        saturation_capacity_e=32691.0,
        dark_current_e_per_s=10.0,
        exposure_time_s=0.01,
        dsnu_e=1.0,
        prnu=0.005,
        black_level_dn=16.0,
    ),
    "webcam": Sensor(
        name="webcam",
        bit_depth=8,
        quantum_efficiency=0.5,
        system_gain_dn_per_e=255 / 6000,
        dark_noise_e=12.0,
        saturation_capacity_e=6000.0,
        dark_current_e_per_s=50.0,
        exposure_time_s=0.033,
        dsnu_e=4.0,
        prnu=0.015,
        black_level_dn=4.0,
    ),
}


def load_sensor(spec: str | Path) -> Sensor:
    """A sensor by preset name (:data:`SENSOR_PRESETS`) or from a YAML/JSON file of
    :class:`Sensor` parameters (unknown keys refused)."""
    from virtus.io.safeio import read_yaml

    if isinstance(spec, str) and spec in SENSOR_PRESETS:
        return SENSOR_PRESETS[spec]
    path = Path(spec)
    if not path.is_file():
        raise InputError(
            "sensor", f"a preset name ({', '.join(SENSOR_PRESETS)}) or a sensor file", str(spec)
        )
    data = read_yaml(path, "sensor file", expect=dict)
    return Sensor.from_dict({"name": path.stem, **data})
