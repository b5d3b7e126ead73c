"""Decoding on the device (:mod:`virtus.render.jit.decode`) against the host decoder.

CI has no GPU: these run the same code on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``.
Frames are synthesised from each sequence's own projector values on a surface that covers
the projector and a little beyond it, with noise, 8-bit quantisation, dark pixels, pixels
around the modulation threshold and saturated ones, in 64 x 80 camera px (not square, so a
transposed layout fails).
"""

from __future__ import annotations

import warnings
import zlib
from dataclasses import replace

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError, VirtusError
from virtus.patterns import (
    DecodeWarning,
    PatternSequence,
    default_sequence,
    load_sequence_file,
)
from virtus.render.backend import mitsuba
from virtus.render.jit.decode import decode_on_device, frames_to_device, supports

VARIANT = "llvm_ad_rgb"
HEIGHT, WIDTH = 64, 80
EXAMPLES = "examples/sequences"
#: Phase agreement in float64 (the default): the same formulas in the same precision, only
#: summation order and atan2's last bit differ (measured 6e-14 rad at 320 rad); a wrong
#: shift, sign or order is off by far more. Masks, flags and orders must be equal: float64
#: decides differently only on edges hit exactly in exact arithmetic (measured 6 of 1.8e6
#: pixels of dark multi-wavelength frames on llvm, 9 on cuda; none in these frames).
PHASE_FLOAT64_RAD = 1e-9
#: Phase RMS agreement asked of either precision; float32 measures 1e-5 rad (one float32
#: unit of an absolute phase of ~300 rad is 3e-5 rad).
PHASE_RMS_RAD = 1e-4
#: Largest float32 phase difference: half a float32 unit at the largest absolute phase
#: (~330 rad on a 912 px axis of period 18) is 1.5e-5 rad, plus the rounding of sums and
#: atan2 (measured 4e-5 rad max over 1.8e6 pixels).
PHASE_FLOAT32_MAX_RAD = 1e-4
#: In float32, pixels within rounding of a decision edge (modulation threshold, residual
#: limits) can decide the other way: measured 2.4e-5 of the pixels for the temporal and
#: heterodyne sequences (45 of 1.8e6 in masks, 30 in flags), none for the codes. At most
#: this share (never more than a couple of pixels in these images).
FLOAT32_EDGE_FRACTION = 5e-4
#: Background and modulation in float64 (DN): sums of at most a few thousand DN (measured
#: 6e-14 DN).
INTENSITY_FLOAT64_DN = 1e-9
#: The same in float32: sums of a few thousand DN round to ~1e-4 DN (measured 4e-5 DN).
INTENSITY_FLOAT32_DN = 1e-3


# --- sequences and frames ---------------------------------------------------------------


def describe(blocks: list[dict], scale: dict | None = None) -> PatternSequence:
    data = {"width": 912, "height": 1140, "blocks": blocks}
    return PatternSequence.from_dict(data | ({"scale": scale} if scale else {}))


def direction(name: str, phase: dict, code: dict | None = None) -> list[dict]:
    """A direction's blocks: a phase set (``phase`` fields) and, given ``code`` fields, a
    7-bit Gray code of the same (single) period."""
    blocks = [{"kind": "phase", "direction": name, "steps": 5} | phase]
    if code is not None:
        code = {"kind": "gray", "period": phase["period"], "bits": 7} | code
        blocks.append(code | {"direction": name})
    return blocks


WHITE_BLACK = [{"kind": "white"}, {"kind": "black"}]
# Each direction decodes on its own, so one sequence covers two codings (one per direction):
# fewer kernels to compile.
SEQUENCES = {
    "default": default_sequence,
    **{
        f"example-{name}": (lambda n=name: load_sequence_file(f"{EXAMPLES}/{n}.yaml")[0])
        for name in ("heterodyne", "lightcrafter_lab", "multiwavelength", "paper")
    },
    # Threshold (mean white + mean black) / 2.
    "gray-plain-v-binary-complement-edge-lsb-h": lambda: describe(
        direction("v", {"period": 18.0, "steps": 9}, {})
        + direction(
            "h",
            {"period": 18.0},
            {"kind": "binary", "complement": True, "align": "edge", "bit_order": "lsb_first"},
        )
        + WHITE_BLACK
    ),
    # No uniform frames: single frames against the phase background, pairs compared.
    "inverted-pairs-v-inverted-complement-h": lambda: describe(
        direction("v", {"period": 18.0, "steps": 4}, {"inverted": True})
        + direction("h", {"period": 18.0}, {"inverted": True, "complement": True})
    ),
    # Black frames only: the phase background again; non-integer period, offset and sign.
    "binary-plain-offset-v-period-17.3-offset-sign-h": lambda: describe(
        direction("v", {"period": 18.0, "offset": -2.0}, {"kind": "binary", "align": "edge"})
        + direction(
            "h", {"period": 17.3, "steps": 7, "offset": 0.7, "sign": -1}, {"complement": True}
        )
        + [{"kind": "black"}] * 3
    ),
    "heterodyne-v-multiwavelength-h": lambda: describe(
        direction("v", {"periods": [20.0, 20.35], "steps": 4})
        + direction("h", {"periods": [1200.0, 170.0, 23.5]})
        + WHITE_BLACK
    ),
    # Window-only "v"; "h" rows counted in pairs (scale 2); ignored and repeated frames.
    "window-v-row-scale-2-h-ignored-frames": lambda: describe(
        [{"kind": "ignore", "count": 2}]
        + direction("v", {"period": 1000.0, "sign": -1})
        + direction("h", {"period": 36.0, "steps": 6}, {"complement": True})
        + [{"kind": "ignore"}, {"kind": "black", "count": 2}, {"kind": "white", "count": 3}],
        scale={"h": 2},
    ),
}


def surface(sequence: PatternSequence, rng, shape=(HEIGHT, WIDTH)) -> tuple[np.ndarray, ...]:
    """Projector coordinates (px) of each camera pixel: a wavy surface over the whole
    projector and up to 2 px beyond it (so the range check acts), with random jitter."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = -2.0 + (sequence.width + 3.0) * cols / (shape[1] - 1) + 3.0 * np.sin(rows / 7.0)
    v = -2.0 + (sequence.height + 3.0) * rows / (shape[0] - 1) + 2.0 * np.cos(cols / 9.0)
    return u + rng.uniform(-0.4, 0.4, shape), v + rng.uniform(-0.4, 0.4, shape)


def synthesise(sequence: PatternSequence, rng, shape=(HEIGHT, WIDTH)) -> np.ndarray:
    """(F, H, W) uint8 frames ``A + B * value + noise`` of the sequence's own projector
    values: B from 0 (dark) through the modulation threshold to 200 DN, a saturated block
    (A + B > 255) and a dark block."""
    u, v = surface(sequence, rng, shape)
    a = rng.uniform(5.0, 60.0, shape)
    b = rng.uniform(0.0, 200.0, shape)
    b[:, :6] = rng.uniform(5.0, 20.0, (shape[0], 6))  # B/2 around 0.02 * 255 = 5.1 DN
    a[:8, 20:28], b[:8, 20:28] = 200.0, 150.0  # saturated
    a[-6:, 30:40], b[-6:, 30:40] = 2.0, 1.0  # dark
    out = np.empty((len(sequence), *shape))
    for index, frame in enumerate(sequence.frames):
        out[index] = a + b * sequence.values(index, u if frame.direction == "v" else v)
    out += rng.normal(0.0, 2.0, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def decode_both(sequence, frames, device_frames=None, **options):
    """(host result, device result) of the same frames, ``decode(neighbour_check=False)``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        host = sequence.decode(frames, neighbour_check=False, **options)
        if device_frames is None:
            device_frames = frames_to_device(frames, VARIANT)
        height, width = frames.shape[1:]
        device = decode_on_device(device_frames, sequence, height, width, **options)
        return host, device.to_host(sequence)


def assert_agree(
    host,
    device,
    sequence,
    *,
    phase_max=PHASE_FLOAT64_RAD,
    intensity=INTENSITY_FLOAT64_DN,
    edge_fraction=0.0,
):
    """Masks, flags and fringe orders equal (up to ``edge_fraction`` of the pixels deciding
    differently at a threshold), phases within ``phase_max`` and RMS ``PHASE_RMS_RAD``,
    modulation and background within ``intensity``."""
    pixels = host.mask.size
    allowed = int(edge_fraction * pixels)
    assert device.mask.shape == host.mask.shape
    assert (device.period_v, device.period_h) == (host.period_v, host.period_h)
    assert device.full_scale == host.full_scale
    for direction in ("v", "h"):
        mask_h, mask_d = getattr(host, f"mask_{direction}"), getattr(device, f"mask_{direction}")
        flag_h = getattr(host, f"flagged_{direction}")
        flag_d = getattr(device, f"flagged_{direction}")
        assert np.count_nonzero(mask_h != mask_d) <= allowed, direction
        assert np.count_nonzero(flag_h != flag_d) <= allowed, direction
        if direction not in sequence.directions:
            assert not mask_d.any() and np.isnan(getattr(device, f"phase_{direction}")).all()
            continue
        assert mask_h.any(), f"nothing valid in {direction}: the test would prove nothing"
        assert (~mask_h).any(), f"everything valid in {direction}: masks are not tested"
        phase_h = getattr(host, f"phase_{direction}")
        phase_d = getattr(device, f"phase_{direction}")
        assert np.array_equal(np.isnan(phase_d), ~mask_d)
        both = mask_h & mask_d
        difference = phase_d[both] - phase_h[both]
        assert np.max(np.abs(difference)) < phase_max, direction  # one fringe order: 2 pi
        assert np.sqrt(np.mean(difference**2)) < PHASE_RMS_RAD
        column = 0 if direction == "v" else 1
        uv_error = device.proj_uv[..., column][both] - host.proj_uv[..., column][both]
        period = sequence.periods(direction)[0] / sequence.axis_scale(direction)
        assert np.max(np.abs(uv_error)) < phase_max * period / (2 * np.pi) * 1.01
        modulation = getattr(device, f"modulation_{direction}")
        assert close(modulation, getattr(host, f"modulation_{direction}"), intensity)
    assert np.count_nonzero(device.mask != host.mask) <= 2 * allowed
    assert close(device.background, host.background, intensity)
    assert close(device.modulation, host.modulation, intensity)


def close(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    return np.allclose(a, b, rtol=0.0, atol=atol, equal_nan=True)


# --- agreement with the host ------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SEQUENCES))
def test_device_decode_equals_host_decode(name: str) -> None:
    sequence = SEQUENCES[name]()
    assert supports(sequence)
    rng = rng_for(name)
    frames = synthesise(sequence, rng)
    host, device = decode_both(sequence, frames, saturation_level=250.0)
    assert_agree(host, device, sequence)
    saturated = host.mask_v[:8, 20:28] if "v" in sequence.directions else host.mask_h[:8, 20:28]
    assert not saturated.any()  # the saturation check did act (on host and device alike)


def test_defaults_full_scale_and_no_saturation_check() -> None:
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("defaults"))
    host, device = decode_both(sequence, frames)
    assert_agree(host, device, sequence)
    assert device.full_scale == 255.0
    host, device = decode_both(sequence, frames, min_modulation=0.1, full_scale=300.0)
    assert_agree(host, device, sequence)


def test_deep_sensor_frames_as_uint32() -> None:
    # A 12-bit sensor: uint16 frames on the host, UInt32 on the device with the full scale.
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("deep")).astype(np.uint16) * 16
    unsaturated = sequence.decode(frames, full_scale=4095.0, neighbour_check=False)
    frames[0, 10:14, 40:44] = 4095  # one phase frame of "v"
    device_frames = frames_to_device(frames, VARIANT)
    mi, _, _ = mitsuba(VARIANT)
    assert isinstance(device_frames, mi.UInt32)
    host, device = decode_both(
        sequence, frames, device_frames, full_scale=4095.0, saturation_level=4095
    )
    assert_agree(host, device, sequence)
    assert unsaturated.mask_v[10:14, 40:44].all() and not device.mask_v[10:14, 40:44].any()


def test_float_frames() -> None:
    sequence = SEQUENCES["inverted-pairs-v-inverted-complement-h"]()
    frames = (synthesise(sequence, rng_for("float")) / np.float32(255.0)).astype(np.float32)
    host, device = decode_both(sequence, frames, saturation_level=0.98)
    assert device.full_scale == 1.0
    assert_agree(host, device, sequence)


def test_sequence_without_fringes_decodes_to_nothing() -> None:
    sequence = PatternSequence(8, 8, tuple(describe(WHITE_BLACK).frames))
    frames = np.full((2, HEIGHT, WIDTH), 100, dtype=np.uint8)
    host, device = decode_both(sequence, frames)
    assert not device.mask.any() and not host.mask.any()
    assert np.isnan(device.proj_uv).all() and np.isnan(device.background).all()


@pytest.mark.parametrize("name", ["default", "heterodyne-v-multiwavelength-h"])
def test_float32_precision_agrees_but_at_decision_edges(name: str) -> None:
    sequence = SEQUENCES[name]()
    frames = synthesise(sequence, rng_for(name))
    result = decode_on_device(
        frames_to_device(frames, VARIANT), sequence, HEIGHT, WIDTH, precision="float32"
    )
    mi, _, _ = mitsuba(VARIANT)
    assert isinstance(result.phase_v, mi.Float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        host = sequence.decode(frames, neighbour_check=False)
        device = result.to_host(sequence)
    assert_agree(
        host,
        device,
        sequence,
        phase_max=PHASE_FLOAT32_MAX_RAD,
        intensity=INTENSITY_FLOAT32_DN,
        edge_fraction=FLOAT32_EDGE_FRACTION,
    )


# --- the device arrays ------------------------------------------------------------------


def test_device_arrays_match_the_host_result() -> None:
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("arrays"))
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, HEIGHT, WIDTH)
    host = result.to_host(sequence)
    assert (result.height, result.width, result.variant) == (HEIGHT, WIDTH, VARIANT)

    def plane(array) -> np.ndarray:
        return np.asarray(array.numpy()).reshape(HEIGHT, WIDTH)

    assert np.array_equal(plane(result.mask), host.mask)
    assert np.array_equal(plane(result.flagged_h), host.flagged_h)
    uv = np.stack([plane(result.u_p), plane(result.v_p)], axis=-1)
    assert np.allclose(uv, host.proj_uv, rtol=0, atol=1e-9, equal_nan=True)
    assert np.allclose(plane(result.modulation), host.modulation, rtol=0, atol=1e-9)
    wrapped = plane(result.wrapped_v)
    assert np.all((wrapped >= -np.pi) & (wrapped < np.pi))
    # The wrapped phase is the absolute phase modulo 2 pi.
    valid = host.mask_v
    residue = (host.phase_v[valid] - wrapped[valid]) / (2 * np.pi)
    assert np.allclose(residue, np.rint(residue), atol=1e-9)


# --- the neighbour check, on the host afterwards ---------------------------------------


def smooth_surface(shape=(48, 64)) -> tuple[np.ndarray, np.ndarray]:
    """A tilted, gently curved surface, 0.7 projector px per camera px (fine fringes)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = 300.0 + 0.7 * cols + 0.15 * rows + 6.0 * np.sin(rows / 40.0)
    v = 500.0 + 0.7 * rows + 0.1 * cols + 4.0 * np.cos(cols / 50.0)
    return u, v


def blurred_lab_frames(sequence: PatternSequence) -> np.ndarray:
    """Lab frames of the smooth surface, defocused and with noisy code frames: the plain
    code is misread near its edges, which makes one-period jumps for the check to find."""
    from scipy import ndimage

    u, v = smooth_surface()
    out = np.empty((len(sequence), *u.shape))
    for index, frame in enumerate(sequence.frames):
        out[index] = 30.0 + 180.0 * sequence.values(index, u if frame.direction == "v" else v)
    out = ndimage.gaussian_filter(out, (0, 1, 1))
    codes = [i for i, f in enumerate(sequence.frames) if f.kind == "gray"]
    out[codes] += np.random.default_rng(4).normal(0.0, 8.0, out[codes].shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def assert_same_result(host, device) -> None:
    for key in ("mask_v", "mask_h", "flagged_v", "flagged_h"):
        assert np.array_equal(getattr(device, key), getattr(host, key)), key
    assert device.repaired == host.repaired
    assert np.allclose(device.proj_uv, host.proj_uv, rtol=0, atol=1e-9, equal_nan=True)


@pytest.mark.parametrize("repair", [False, True])
def test_neighbour_check_runs_on_the_host_as_decode_runs_it(repair: bool) -> None:
    sequence = load_sequence_file(f"{EXAMPLES}/lightcrafter_lab.yaml")[0]
    frames = blurred_lab_frames(sequence)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        host = sequence.decode(frames, repair=repair)
        unchecked = sequence.decode(frames, neighbour_check=False)
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, *frames.shape[1:])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        device = result.to_host(sequence, neighbour_check=None, repair=repair)
    assert_same_result(host, device)
    if repair:
        assert host.repaired > 0  # the frames do have order jumps to repair
    else:
        # ... which the check flags, and which to_host() without it leaves unflagged.
        assert host.flagged.sum() > unchecked.flagged.sum()
        assert_same_result(unchecked, result.to_host(sequence))


def test_neighbour_check_default_skips_per_pixel_checked_directions() -> None:
    # With the complementary frame decode runs no neighbour check by default; forced on,
    # both run it the same way.
    sequence = default_sequence()
    u, v = smooth_surface()
    frames = np.empty((len(sequence), *u.shape))
    for index, frame in enumerate(sequence.frames):
        frames[index] = 30.0 + 180.0 * sequence.values(index, u if frame.direction == "v" else v)
    frames = np.rint(frames).astype(np.uint8)
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, *frames.shape[1:])
    assert_same_result(sequence.decode(frames), result.to_host(sequence, neighbour_check=None))
    assert_same_result(
        sequence.decode(frames, neighbour_check=True),
        result.to_host(sequence, neighbour_check=True),
    )


def test_to_host_warns_as_decode_does() -> None:
    # Frames of an edge-aligned complementary code read as centre-aligned: most pixels fall
    # outside their half-period cell and are flagged per pixel.
    def code(align: str) -> PatternSequence:
        blocks = {"period": 18.0, "steps": 18}, {"complement": True, "align": align, "bits": 6}
        return describe(direction("v", *blocks) + direction("h", *blocks) + WHITE_BLACK)

    truth, wrong = code("edge"), code("centre")  # wrong: the default sequence
    frames = synthesise(truth, rng_for("warn"))
    with pytest.warns(DecodeWarning):
        host = wrong.decode(frames, neighbour_check=False)
    result = decode_on_device(frames_to_device(frames, VARIANT), wrong, HEIGHT, WIDTH)
    with pytest.warns(DecodeWarning, match="description"):
        device = result.to_host(wrong)
    assert_same_result(host, device)


# --- bad input --------------------------------------------------------------------------


def test_bad_frames_and_options_raise_input_error() -> None:
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("bad"))
    device_frames = frames_to_device(frames, VARIANT)
    with pytest.raises(InputError, match="frames"):
        decode_on_device(device_frames, sequence, HEIGHT, WIDTH + 1)
    with pytest.raises(InputError, match="frames"):
        decode_on_device(frames, sequence, HEIGHT, WIDTH)  # numpy, not uploaded
    with pytest.raises(InputError, match="full_scale"):
        decode_on_device(device_frames, sequence, HEIGHT, WIDTH, full_scale=200.0)
    with pytest.raises(InputError, match="full_scale"):
        decode_on_device(frames_to_device(frames.astype(np.uint16), VARIANT), sequence, 64, 80)
    with pytest.raises(InputError, match="min_modulation"):
        decode_on_device(device_frames, sequence, HEIGHT, WIDTH, min_modulation=1.0)
    with pytest.raises(InputError, match="precision"):
        decode_on_device(device_frames, sequence, HEIGHT, WIDTH, precision="float16")
    nonfinite = frames.astype(np.float32) / 255
    nonfinite[3, 5, 5] = np.nan
    with pytest.raises(InputError, match="finite"):
        decode_on_device(frames_to_device(nonfinite, VARIANT), sequence, HEIGHT, WIDTH)
    with pytest.raises(InputError, match="full_scale"):
        decode_on_device(frames_to_device(frames * 1.0, VARIANT), sequence, HEIGHT, WIDTH)
    result = decode_on_device(device_frames, sequence, HEIGHT, WIDTH)
    with pytest.raises(InputError, match="sequence"):
        result.to_host(SEQUENCES["example-heterodyne"]())


def test_unsupported_plan_is_refused_clearly() -> None:
    sequence = default_sequence()
    plans = dict(sequence._plans)
    plans["v"] = replace(plans["v"], method="a method of the future")
    object.__setattr__(sequence, "_plans", plans)
    assert not supports(sequence)
    frames = frames_to_device(np.zeros((len(sequence), 4, 4), np.uint8), VARIANT)
    with pytest.raises(VirtusError, match="unsupported"):
        decode_on_device(frames, sequence, 4, 4)


# --- against ground truth, not only against the host ------------------------------------
# A mistake made in both decoders passes every host-vs-device comparison above; these
# compare the device decode (and the host's) with the exact projector coordinates.


def plane_coordinates(sequence: PatternSequence, shape=(HEIGHT, WIDTH)) -> tuple[np.ndarray, ...]:
    """Exact projector coordinates (px) of each camera pixel of a gently curved surface
    inside the projector (0.5 px from its ends)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    du = 2.0 * np.sin(rows / 7.0) * np.sin(np.pi * cols / (shape[1] - 1))
    dv = 1.5 * np.cos(cols / 9.0) * np.sin(np.pi * rows / (shape[0] - 1))
    u = 0.5 + (sequence.width - 2.0) * cols / (shape[1] - 1) + du
    v = 0.5 + (sequence.height - 2.0) * rows / (shape[0] - 1) + dv
    return u, v


def near_plain_code_edges(sequence: PatternSequence, direction: str, w: np.ndarray) -> np.ndarray:
    """Pixels whose coordinate lies within CODE_EDGE_BAND_PX of an edge of a code without
    the complementary frame (ambiguous there by design, see tests/patterns/test_codings.py)."""
    from tests.patterns.test_codings import code_edges

    plan = sequence.plans()[direction]
    if plan.code is None or plan.code.coding.complement:
        return np.zeros(w.shape, dtype=bool)
    edges = code_edges(sequence, direction)
    return np.min(np.abs(w[..., None] - edges), axis=-1) < tol.CODE_EDGE_BAND_PX


@pytest.mark.parametrize("name", sorted(SEQUENCES))
def test_device_decode_of_ideal_frames_gives_the_true_coordinates(name: str) -> None:
    sequence = SEQUENCES[name]()
    u, v = plane_coordinates(sequence)
    frames = np.empty((len(sequence), HEIGHT, WIDTH))
    for index, frame in enumerate(sequence.frames):
        frames[index] = 30.0 + 180.0 * sequence.values(index, u if frame.direction == "v" else v)
    frames = np.rint(frames).astype(np.uint8)
    host, device = decode_both(sequence, frames)
    for result in (device, host):
        for column, (direction, truth) in enumerate((("v", u), ("h", v))):
            mask = getattr(result, f"mask_{direction}")
            assert mask.all(), direction  # every pixel lies on the projector
            keep = ~near_plain_code_edges(sequence, direction, truth)
            error = np.abs(result.proj_uv[..., column] - truth)[keep]
            profiles = {f.profile for f in sequence.frames if f.direction == direction}
            if profiles & {"binary", "dithered"}:
                assert error.max() < tol.DECODE_BINARY_MAX_PX, direction  # a staircase
            else:
                # 8-bit rounding of the fringes: a phase error, px in proportion to T.
                period = sequence.periods(direction)[0] / sequence.axis_scale(direction)
                phase_error = error.max() * 2 * np.pi / period
                assert phase_error < tol.DECODE_PHASE_8BIT_FEW_STEPS_RAD, direction


def test_device_heavy_noise_leaves_no_valid_pixel_half_a_period_off() -> None:
    # The residual mask on the device (tests/patterns/test_decode_reliability.py on the host).
    from tests.patterns.test_decode_reliability import (
        HEAVY_NOISE_AMPLITUDE_DN,
        heavy_noise_frames,
        order_errors,
    )

    for name in sorted(HEAVY_NOISE_AMPLITUDE_DN):
        sequence, frames, u, v = heavy_noise_frames(name)
        result = decode_on_device(frames_to_device(frames, VARIANT), sequence, *frames.shape[1:])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DecodeWarning)
            device = result.to_host(sequence)
        assert order_errors(device, sequence, u, v) == 0, name
        assert device.mask.mean() > 0.5, name


@pytest.mark.parametrize("method", ["temporal", "heterodyne"])
def test_device_flags_and_masks_pixels_by_their_residual(method: str) -> None:
    from tests.patterns.test_decode_reliability import (
        CLEAN_RAD,
        CRAFTED,
        FLAGGED_RAD,
        INVALID_RAD,
        crafted_frames,
        residual_groups,
    )

    sequence, erred = CRAFTED[method]
    shares = {CLEAN_RAD: 500, FLAGGED_RAD: 300, INVALID_RAD: 200}
    u, v, residual = residual_groups(shares, 5)
    frames = crafted_frames(sequence, erred, u, v, residual / 8.0).astype(np.float32)
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, *frames.shape[1:])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        device = result.to_host(sequence)
    for direction in ("v", "h"):
        mask = getattr(device, f"mask_{direction}")
        np.testing.assert_array_equal(mask, residual <= FLAGGED_RAD, err_msg=direction)
        flagged = getattr(device, f"flagged_{direction}")
        np.testing.assert_array_equal(flagged, residual == FLAGGED_RAD, err_msg=direction)


def test_device_decodes_offset_and_negative_sign_to_the_true_coordinates() -> None:
    from tests.patterns.test_codings import formula_frames, offset_sign_sequence

    sequence = offset_sign_sequence("offset-0.5-sign-minus")
    u, v = plane_coordinates(sequence)
    frames = np.rint(formula_frames(sequence, u, v, 25.0, 190.0)).astype(np.uint8)
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, HEIGHT, WIDTH)
    device = result.to_host(sequence)
    assert device.mask.all()
    error = device.proj_uv - np.stack([u, v], axis=-1)
    assert np.max(np.abs(error)) < tol.DECODE_MAX_PX
