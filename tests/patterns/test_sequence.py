"""Pattern sequences: encoding, frame order, ideal encode -> decode round trips, noise, I/O."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError
from virtus.patterns import (
    DecodeResult,
    Frame,
    PatternSequence,
    build_sequence,
    default_sequence,
    heterodyne_sequence,
)

TWO_PI = 2.0 * np.pi


def ideal_frames(
    sequence: PatternSequence,
    u: np.ndarray,
    v: np.ndarray,
    a: np.ndarray | float,
    b: np.ndarray | float,
) -> np.ndarray:
    """Ideal camera images ``I = A + B * pattern`` at exact projector coordinates ``(u, v)``.

    Phase frames use the continuous cosine at the exact coordinate (built here from the
    frame description, not from the code under test); binary frames the value the projector
    shows at the pixel containing the coordinate. Returns float64 ``(F, *u.shape)``.
    """
    out = np.empty((len(sequence), *u.shape))
    for i, frame in enumerate(sequence.frames):
        coordinate = u if frame.direction == "v" else v
        if frame.kind == "phase":
            shift = TWO_PI * frame.step / frame.steps
            value = 0.5 + 0.5 * np.cos(TWO_PI * coordinate / frame.period + shift)
        elif frame.kind in ("white", "black"):
            value = sequence.profile(i)[0]
        else:
            value = sequence.profile(i)[np.floor(coordinate + 0.5).astype(int)]
        out[i] = a + b * value
    return out


def sample_coordinates(
    rng: np.random.Generator, width: int, height: int, periods: list[float], count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Random projector coordinates over the whole projector plus points within 0.01 px of
    every half period (order edges, where the wrapped phase jumps, and Gray edges)."""
    u = rng.uniform(-0.5, width - 0.5, count)
    v = rng.uniform(-0.5, height - 0.5, count)
    edge_u, edge_v = [], []
    for period in periods:
        for span, edges in ((width, edge_u), (height, edge_v)):
            half = np.arange(0, span, period / 2)
            edges.append(np.concatenate([half - 0.01, half + 0.01, half]))
    edge_u = np.concatenate(edge_u)
    edge_v = np.concatenate(edge_v)
    size = max(edge_u.size, edge_v.size)
    # Pair edge coordinates of one axis with random ones of the other.
    edge_u = np.concatenate([edge_u, rng.uniform(-0.5, width - 0.5, size - edge_u.size)])
    edge_v = np.concatenate([edge_v, rng.uniform(-0.5, height - 0.5, size - edge_v.size)])
    u = np.clip(np.concatenate([u, edge_u]), -0.5, width - 0.5 - 1e-9)
    v = np.clip(np.concatenate([v, edge_v]), -0.5, height - 0.5 - 1e-9)
    return u, v


# --- the default sequence ---------------------------------------------------------------


def test_default_sequence_frame_count_and_order() -> None:
    sequence = default_sequence()
    assert (sequence.width, sequence.height, len(sequence)) == (912, 1140, 52)
    expected = []
    for direction in ("v", "h"):
        expected += [("phase", direction, 18.0, n, 18, None, None) for n in range(1, 19)]
        expected += [("gray", direction, 18.0, None, None, b, 6) for b in range(1, 7)]
        expected += [("gray_complement", direction, 18.0, None, None, None, None)]
    expected += [("white",) + (None,) * 6, ("black",) + (None,) * 6]
    got = [(f.kind, f.direction, f.period, f.step, f.steps, f.bit, f.bits) for f in sequence.frames]
    assert got == expected
    described = sequence.describe()
    assert [d["index"] for d in described] == list(range(52))
    assert described[0] == {
        "index": 0,
        "kind": "phase",
        "direction": "v",
        "period": 18.0,
        "step": 1,
        "steps": 18,
    }
    assert described[18] == {
        "index": 18,
        "kind": "gray",
        "direction": "v",
        "period": 18.0,
        "bit": 1,
        "bits": 6,
    }
    assert described[50] == {"index": 50, "kind": "white"}


def test_profiles_images_and_8bit_values() -> None:
    sequence = default_sequence()
    images = sequence.images()
    assert images.shape == (52, 1140, 912) and images.dtype == np.uint8
    for index, frame in enumerate(sequence.frames):
        profile = sequence.profile(index)
        length = {"v": 912, "h": 1140, None: 1}[frame.direction]
        assert profile.shape == (length,) and profile.dtype == np.float64
        np.testing.assert_array_equal(profile * 255, np.rint(profile * 255))  # 8-bit levels
        assert profile.min() >= 0.0 and profile.max() <= 1.0
        image = sequence.image(index)
        assert image.shape == (1140, 912)
        np.testing.assert_array_equal(np.rint(image * 255).astype(np.uint8), images[index])
    np.testing.assert_array_equal(images[5][:, 100], images[5][0, 100])  # "v": constant columns
    np.testing.assert_array_equal(images[30][100, :], images[30][100, 0])  # "h": constant rows
    assert np.all(images[50] == 255) and np.all(images[51] == 0)


def test_phase_profile_sign_and_origin_with_non_integer_period() -> None:
    period, steps = 17.3, 5
    sequence = build_sequence(40, 30, periods=period, steps=steps, gray_bits=2)
    j = np.arange(40)
    for n in range(1, steps + 1):
        expected = np.rint(255 * (0.5 + 0.5 * np.cos(TWO_PI * j / period + TWO_PI * n / steps)))
        np.testing.assert_array_equal(sequence.profile(n - 1) * 255, expected)
    # The phase origin is the centre of column 0: step N (shift 2 pi) is brightest there.
    assert sequence.profile(steps - 1)[0] == 1.0


def test_gray_code_numbers_fringe_orders_and_complement_shifts_by_half_a_period() -> None:
    period, bits = 18.0, 6
    sequence = default_sequence()
    gray = [sequence.index_of("gray", "h", bit=b) for b in range(1, bits + 1)]
    complement = sequence.index_of("gray_complement", "h")
    v = np.arange(1140)
    code = np.zeros(1140, dtype=np.int64)
    for index in gray:
        code = (code << 1) | sequence.profile(index).astype(np.int64)
    code = (code << 1) | sequence.profile(complement).astype(np.int64)
    # Gray -> binary: the (bits + 1)-bit code counts half periods g = floor(2 v / T + 1).
    binary = code.copy()
    shift = binary >> 1
    while np.any(shift):
        binary ^= shift
        shift >>= 1
    np.testing.assert_array_equal(binary, np.floor(2 * v / period + 1))
    changes = np.flatnonzero(np.diff(code)) + 0.5  # between pixel centres
    np.testing.assert_allclose(
        changes, np.arange(1, changes.size + 1) * period / 2, atol=tol.GRAY_EDGE_PX
    )


# --- decoding ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [default_sequence, heterodyne_sequence],
    ids=["default", "heterodyne"],
)
def test_ideal_encode_decode_round_trip(make) -> None:
    sequence = make()
    rng = np.random.default_rng(2024)
    periods = sorted({f.period for f in sequence.frames if f.kind == "phase"})
    u, v = sample_coordinates(rng, sequence.width, sequence.height, periods, 20000)
    a = rng.uniform(10, 60, u.size)
    b = rng.uniform(120, 190, u.size)  # fringe modulation B / 2 = 60..95 DN
    frames = np.rint(ideal_frames(sequence, u, v, a, b)).astype(np.uint8)[:, np.newaxis, :]
    result = sequence.decode(frames)
    assert isinstance(result, DecodeResult)
    assert result.proj_uv.shape == (1, u.size, 2) and result.mask.shape == (1, u.size)
    assert result.mask.all()
    error = result.proj_uv[0] - np.stack([u, v], axis=-1)
    rms = np.sqrt(np.mean(error**2, axis=0))
    assert np.all(rms < tol.DECODE_RMS_PX), rms
    assert np.max(np.abs(error)) < tol.DECODE_MAX_PX  # no fringe-order error anywhere
    np.testing.assert_allclose(
        result.phase_v[0], TWO_PI * u / periods[0], atol=tol.DECODE_PHASE_8BIT_RAD
    )
    np.testing.assert_allclose(result.background[0], a + b / 2, atol=tol.INTENSITY_8BIT_DN)
    np.testing.assert_allclose(result.modulation[0], b / 2, atol=tol.INTENSITY_8BIT_DN)


def test_decode_without_uniform_frames_thresholds_on_the_phase_background() -> None:
    sequence = build_sequence(
        300, 200, periods=12.5, steps=4, gray_bits=5, white=False, black=False
    )
    rng = np.random.default_rng(5)
    u, v = sample_coordinates(rng, 300, 200, [12.5], 3000)
    frames = ideal_frames(sequence, u, v, 30.0, 150.0)[:, np.newaxis, :]
    result = sequence.decode(frames, full_scale=255.0)
    assert result.mask.all()
    error = result.proj_uv[0] - np.stack([u, v], axis=-1)
    assert np.max(np.abs(error)) < tol.DECODE_EXACT_PX


@pytest.mark.parametrize("steps", [3, 18])
def test_phase_noise_matches_theory(steps: int) -> None:
    # sigma_phi = (sigma / B) sqrt(2 / N) for I_n = A + B cos(...) + N(0, sigma^2), B in DN.
    sigma, a, b_image = 2.0, 60.0, 160.0  # I = A + b_image * (0.5 + 0.5 cos): B = 80 DN
    # One period longer than the 64 px axis: absolute without unwrapping, slack at both ends.
    sequence = build_sequence(64, 2, periods=100.0, steps=steps, directions=("v",))
    rng = np.random.default_rng(steps)
    u = rng.uniform(5.0, 58.0, (200, 200))  # >= 10 sigma from the decodable range's ends
    clean = ideal_frames(sequence, u, np.zeros_like(u), a, b_image)
    noisy = clean + rng.normal(0.0, sigma, clean.shape)
    result = sequence.decode(noisy, full_scale=255.0)
    assert result.mask.all()
    measured = np.std(result.phase_v - TWO_PI * u / 100.0)
    expected = sigma / (b_image / 2) * np.sqrt(2.0 / steps)
    assert abs(measured / expected - 1.0) < tol.NOISE_STD_REL, (measured, expected)


def test_quality_mask_rejects_dark_and_saturated_pixels() -> None:
    sequence = default_sequence()
    u = np.array([100.2, 200.7, 300.1])
    v = np.array([50.5, 500.3, 900.9])
    frames = ideal_frames(sequence, u, v, np.array([20.0, 0.0, 20.0]), np.array([150, 3, 250]))
    frames = np.clip(frames, 0, 255)[:, np.newaxis, :]  # the sensor clips: pixel 2 saturates
    result = sequence.decode(frames.astype(np.uint8), saturation_level=255)
    np.testing.assert_array_equal(result.mask[0], [True, False, False])
    assert np.isnan(result.proj_uv[0, 1]).all() and np.isnan(result.phase_v[0, 2])
    assert result.mask_v[0, 0] and result.mask_h[0, 0]


def test_absent_direction_gives_nan() -> None:
    sequence = build_sequence(120, 80, periods=10.0, steps=4, gray_bits=4, directions=("v",))
    u = np.array([[3.3, 77.7]])
    frames = ideal_frames(sequence, u, np.zeros_like(u), 20.0, 200.0)
    result = sequence.decode(frames, full_scale=255.0)
    assert result.period_h is None and result.period_v == 10.0
    assert np.isnan(result.phase_h).all() and np.isnan(result.proj_uv[..., 1]).all()
    assert not result.mask_h.any()
    np.testing.assert_array_equal(result.mask, result.mask_v)
    np.testing.assert_allclose(result.proj_uv[..., 0], u, atol=tol.DECODE_EXACT_PX)
    uniform_only = PatternSequence(120, 80, (Frame("white"), Frame("black")))
    assert not uniform_only.decode(np.zeros((2, 3, 4), dtype=np.uint8)).mask.any()


# --- description and files --------------------------------------------------------------


def test_to_dict_from_dict_is_lossless() -> None:
    for sequence in (default_sequence(), heterodyne_sequence(500, 700, steps=(3, 4, 5))):
        data = json.loads(json.dumps(sequence.to_dict()))
        back = PatternSequence.from_dict(data)
        assert (back.width, back.height) == (sequence.width, sequence.height)
        assert back.frames == sequence.frames  # periods such as 1152/63 survive exactly
        assert back == sequence and hash(back) == hash(sequence)
        np.testing.assert_array_equal(back.profile(7), sequence.profile(7))


def test_cli_writes_pngs_and_sequence_json(tmp_path) -> None:
    from virtus.cli import main

    out = tmp_path / "patterns"
    with pytest.raises(SystemExit) as info:
        main(["patterns", "--out", str(out)])
    assert info.value.code == 0
    files = sorted(out.glob("*.png"))
    assert [f.name for f in files] == [f"{i:03d}.png" for i in range(52)]
    reference = default_sequence()
    for index in (0, 24, 31, 51):
        image = cv2.imread(str(files[index]), cv2.IMREAD_UNCHANGED)
        assert image.shape == (1140, 912) and image.dtype == np.uint8
        np.testing.assert_array_equal(image, np.rint(reference.image(index) * 255))
    data = json.loads((out / "sequence.json").read_text())
    assert [frame["file"] for frame in data["frames"]] == [f.name for f in files]
    assert PatternSequence.from_dict(data).frames == reference.frames


# --- bad input --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"steps": 2}, "steps"),
        ({"periods": 0.0}, "periods"),
        ({"periods": -18.0}, "periods"),
        ({"gray_bits": 0}, "gray_bits"),
        ({"gray_bits": 3}, "bits"),  # 8 orders of 18 px cannot number 1140 px
        ({"periods": (18.0, 18.5), "gray_bits": None}, "frames"),  # beat 666 px < 1140 px
    ],
)
def test_bad_sequence_arguments_raise_input_error(kwargs, name) -> None:
    arguments = {"periods": 18.0, "steps": 18, "gray_bits": 6} | kwargs
    with pytest.raises(InputError) as info:
        build_sequence(912, 1140, **arguments)
    assert info.value.name == name


def test_bad_frames_raise_input_error() -> None:
    with pytest.raises(InputError) as info:
        Frame("phase", "v", 18.0, step=1, steps=2)
    assert info.value.name == "steps"
    with pytest.raises(InputError) as info:
        Frame("gray", "v", 18.0, bit=1, bits=0)
    assert info.value.name == "bits"


def test_bad_decode_input_raises_input_error() -> None:
    sequence = build_sequence(64, 2, periods=64.0, steps=3, directions=("v",), white=False)
    good = np.full((len(sequence), 4, 5), 100.0)
    for frames in (good[:-1], good[0], good.astype(complex)):
        with pytest.raises(InputError) as info:
            sequence.decode(frames)
        assert info.value.name == "frames"
    bad = good.copy()
    bad[1, 2, 3] = np.nan
    with pytest.raises(InputError) as info:
        sequence.decode(bad)
    assert info.value.name == "frames" and "non-finite" in str(info.value)


def test_float_frames_above_full_scale_are_refused():
    sequence = default_sequence(64, 48)
    frames = np.full((len(sequence), 4, 4), 200.0)  # DN values in a float array
    with pytest.raises(InputError, match=r"^frames: expected values <= full_scale \(1\)"):
        sequence.decode(frames)
    assert sequence.decode(frames, full_scale=255.0).mask.shape == (4, 4)
