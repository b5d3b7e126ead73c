"""Codes alone (no phase frames): Gray and plain binary codes decoded to the projector column
and row of each camera pixel, and OpenCV's ``GrayCodePattern`` capture as one line of a
sequence file."""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from virtus.errors import InputError, VirtusError
from virtus.patterns import (
    DecodeWarning,
    PatternSequence,
    default_sequence,
    load_sequence_file,
    opencv_graycode_sequence,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "sequences" / "opencv_graycode.yaml"
SIZES = [(912, 1140), (1920, 1080)]
#: camera image (rows, cols): three horizontal bands, each a smooth surface seeing the start,
#: the middle (the most significant bit's edge) and the end of the projector.
CAMERA = (96, 128)
#: projector px per camera px along each axis (the surface's local scale).
K = 0.7
#: sub-samples per camera pixel and axis: pixels on a stripe edge mix both stripes.
SUB = 3
#: half the footprint of a camera pixel in projector px: (K / 2) (1 - 1 / SUB) plus the
#: cross term 0.15 K (1 - 1 / SUB) / 2; a right decode lies within half a stripe of it.
FOOTPRINT = {"v": 0.5 * K * (1 - 1 / SUB) * 1.15, "h": 0.5 * K * (1 - 1 / SUB) * 1.1}
#: binary (non-Gray) codes misread pixels on edges where several bits change: a mixed pixel
#: passes the contrast test on each bit with its own noise (measured below 1e-3 with
#: inverse frames, 6e-3 without, at 40 DN contrast, sigma 3 DN, ambient 150 DN).
BINARY_WRONG_MAX = {True: 2e-3, False: 1e-2}


# --- the reference: what the projector shows, written from the documented conventions --


def opencv_reference(width: int, height: int, uniform=("white", "black")) -> np.ndarray:
    """OpenCV ``GrayCodePattern.generate`` by its documented algorithm, plus the uniform
    frames: per axis ``ceil(log2 size)`` bit planes of the Gray code ``g = i ^ (i >> 1)``,
    most significant first, the plane (255 where the bit is 1) then its inverse; columns,
    then rows."""
    frames = []
    for span, along_columns in ((width, True), (height, False)):
        bits = int(np.ceil(np.log2(span)))
        index = np.arange(span)
        gray = index ^ (index >> 1)
        for shift in range(bits - 1, -1, -1):
            plane = ((gray >> shift) & 1).astype(np.uint8) * 255
            line = plane[np.newaxis, :] if along_columns else plane[:, np.newaxis]
            image = np.broadcast_to(line, (height, width))
            frames += [image, 255 - image]
    for kind in uniform:
        frames.append(np.full((height, width), 255 if kind == "white" else 0, dtype=np.uint8))
    return np.stack(frames)


def shown(frame, coordinate: np.ndarray) -> np.ndarray:
    """What an edge-aligned code frame (scale 1) shows at projector coordinates: pixel
    ``j = floor(c + 1/2)`` shows stripe ``k = floor(j / T)``, whose Gray or binary word's bit
    ``bit`` (1 = most significant) the frame shows, inverted if asked; white 1, black 0."""
    if frame.kind in ("white", "black"):
        return np.full(coordinate.shape, 1.0 if frame.kind == "white" else 0.0)
    assert frame.align == "edge"
    pixel = np.floor(coordinate + 0.5)
    k = np.floor(pixel / frame.period + 1e-12).astype(np.int64)
    word = k ^ (k >> 1) if frame.kind == "gray" else k
    value = ((word >> (frame.bits - frame.bit)) & 1).astype(np.float64)
    return 1.0 - value if frame.inverted else value


def surface(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Projector coordinates ``(u, v)`` seen by each camera pixel: three bands of smooth,
    slightly sheared surfaces (start, middle and end of both projector axes), clipped to the
    projector."""
    rows, cols = np.mgrid[0 : CAMERA[0], 0 : CAMERA[1]].astype(np.float64)
    band = (rows // 32).astype(int)
    r = rows - 32 * band
    u_start = np.array([-0.4, width / 2 - 0.5 * K * CAMERA[1], width - 0.6 - K * CAMERA[1]])
    v_start = np.array([-0.4, height / 2 - 11.0, height - 0.6 - 1.2 * K * 32])
    u = u_start[band] + K * cols + 0.15 * K * r + 0.5 * np.sin(r / 9.0)
    v = v_start[band] + K * r + 0.1 * K * cols + 0.5 * np.cos(cols / 20.0)
    return np.clip(u, -0.5, width - 0.5 - 1e-6), np.clip(v, -0.5, height - 0.5 - 1e-6)


def render(
    sequence: PatternSequence,
    u: np.ndarray,
    v: np.ndarray,
    *,
    ambient: float | np.ndarray,
    gain: float | np.ndarray,
    sigma: float = 0.0,
    seed: int = 0,
    directions: tuple[str, ...] = ("v", "h"),
) -> np.ndarray:
    """8-bit camera frames ``ambient + gain * (mean of what the SUB x SUB sub-samples of
    each camera pixel see) + noise``, clipped at 255 (saturation): the white and black
    frames and the code frames of ``directions`` (others stay dark)."""
    offsets = (np.arange(SUB) + 0.5) / SUB - 0.5
    out = np.zeros((len(sequence), *u.shape))
    for dy in offsets:
        for dx in offsets:
            uu = np.clip(u + K * dx + 0.15 * K * dy, -0.5, sequence.width - 0.5 - 1e-6)
            vv = np.clip(v + K * dy + 0.1 * K * dx, -0.5, sequence.height - 0.5 - 1e-6)
            for index, frame in enumerate(sequence.frames):
                if frame.direction in (None, *directions):
                    out[index] += shown(frame, uu if frame.direction == "v" else vv)
    out = ambient + gain * out / SUB**2
    out += np.random.default_rng(seed).normal(0.0, sigma, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def code_only(
    width: int,
    height: int,
    code: str = "gray",
    order: str = "msb_first",
    inverted: bool = True,
    bits: int | None = None,
    uniform: bool = True,
) -> PatternSequence:
    """Both directions coded alone (default period: a word per projector pixel with
    ``ceil(log2 size)`` bits, else ``size / 2**bits`` px stripes), white and black last."""
    blocks = []
    for direction, span in (("v", width), ("h", height)):
        count = bits or (span - 1).bit_length()
        blocks.append(
            {"kind": code, "direction": direction, "bits": count, "bit_order": order}
            | {"inverted": inverted}
        )
    if uniform:
        blocks += [{"kind": "white"}, {"kind": "black"}]
    return PatternSequence.from_dict({"width": width, "height": height, "blocks": blocks})


def decode(sequence: PatternSequence, frames: np.ndarray, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sequence.decode(frames, **options)
    return result, [w for w in caught if issubclass(w.category, DecodeWarning)]


def wrong(result, u: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    """Per direction decoded from a code alone, valid pixels off by more than half a stripe
    (its widest run of projector pixels) beyond the camera pixel's footprint."""
    out = {}
    for axis, (direction, true) in enumerate((("v", u), ("h", v))):
        stripe = getattr(result, f"stripe_{direction}")
        if stripe is None:
            continue
        limit = 0.5 * np.ceil(stripe) + FOOTPRINT[direction] + 1e-9
        error = np.abs(result.proj_uv[..., axis] - true)
        out[direction] = getattr(result, f"mask_{direction}") & ~(error <= limit)
    return out


# --- OpenCV's GrayCodePattern -----------------------------------------------------------


@pytest.mark.parametrize(("width", "height"), [*SIZES, (1024, 768)])
def test_opencv_preset_is_opencvs_frames_pixel_for_pixel(width: int, height: int) -> None:
    data = {"width": width, "height": height, "preset": "opencv_graycode"}
    sequence = PatternSequence.from_dict(data)
    bits = int(np.ceil(np.log2(width))) + int(np.ceil(np.log2(height)))
    assert len(sequence) == 2 * bits + 2  # 44, 46, 42
    np.testing.assert_array_equal(sequence.images(), opencv_reference(width, height))
    assert sequence == opencv_graycode_sequence(width, height)
    assert sequence.plans()["v"].method == sequence.plans()["h"].method == "code_only"


def test_opencv_preset_matches_cv2_structured_light_when_installed() -> None:
    if not hasattr(cv2, "structured_light"):
        pytest.skip("opencv-contrib (cv2.structured_light) is not installed")
    width, height = 912, 1140
    module = cv2.structured_light
    create = getattr(module, "GrayCodePattern_create", None) or module.GrayCodePattern.create
    pattern = create(width, height)
    _, images = pattern.generate()
    black, white = pattern.getImagesForShadowMasks(
        np.zeros((height, width), np.uint8), np.zeros((height, width), np.uint8)
    )
    expected = np.stack([*images, white, black])
    np.testing.assert_array_equal(opencv_graycode_sequence(width, height).images(), expected)


def test_example_file_and_preset_options() -> None:
    sequence, files = load_sequence_file(EXAMPLE)
    assert sequence == opencv_graycode_sequence(912, 1140) and files is None
    assert len(sequence) == 44 and [f.kind for f in sequence.frames[-2:]] == ["white", "black"]
    base = {"width": 40, "height": 30, "preset": "opencv_graycode"}
    none = PatternSequence.from_dict(base | {"white_black": False})
    assert len(none) == 2 * 6 + 2 * 5 and {f.kind for f in none.frames} == {"gray"}
    swapped = PatternSequence.from_dict(base | {"white_black": ["black", "white"]})
    np.testing.assert_array_equal(
        swapped.images(), opencv_reference(40, 30, uniform=("black", "white"))
    )
    # The per-frame form written by to_dict() reads back as the same sequence.
    assert PatternSequence.from_dict(swapped.to_dict()) == swapped
    for bad, name in [
        ({"preset": "opencv"}, "preset"),
        ({"blocks": [{"kind": "white"}]}, "preset"),
        ({"scale": {"h": 2}}, "preset"),
        ({"white_black": "yes"}, "white_black"),
        ({"white_black": ["white", "white"]}, "white_black"),
        ({"width": 1}, "width"),
    ]:
        with pytest.raises(InputError) as info:
            PatternSequence.from_dict(base | bad)
        assert info.value.name == name, bad
    with pytest.raises(InputError) as info:
        PatternSequence.from_dict(
            {"width": 4, "height": 4, "blocks": [{"kind": "white"}]} | {"white_black": True}
        )
    assert info.value.name == "white_black"


def test_saved_pngs_are_opencvs_patterns(tmp_path) -> None:
    sequence = opencv_graycode_sequence(40, 30)
    sequence.save(tmp_path)
    files = sorted(tmp_path.glob("*.png"))
    images = np.stack([cv2.imread(str(f), cv2.IMREAD_UNCHANGED) for f in files])
    np.testing.assert_array_equal(images, opencv_reference(40, 30))


def test_opencv_capture_decodes_to_column_and_row_indices() -> None:
    # The camera sees the projector pixel for pixel (ideal images of the patterns).
    sequence = load_sequence_file(EXAMPLE)[0]
    result, warned = decode(sequence, sequence.images())
    assert result.mask.all() and not result.flagged.any() and not warned
    rows, cols = np.mgrid[0:1140, 0:912]
    np.testing.assert_array_equal(result.proj_uv[..., 0], cols)
    np.testing.assert_array_equal(result.proj_uv[..., 1], rows)
    assert np.isnan(result.phase_v).all() and np.isnan(result.phase_h).all()
    assert result.period_v is None and result.stripe_v == result.stripe_h == 1.0
    np.testing.assert_array_equal(result.confidence, 255.0)
    np.testing.assert_array_equal(result.background, 127.5)
    summary = result.summary()
    assert summary["valid_fraction"] == 1.0
    assert summary["v"]["period"] is None and summary["h"]["stripe"] == 1.0


def test_opencv_rule_is_reproduced_with_its_threshold() -> None:
    # OpenCV's getProjPixel: bit = pattern > inverse, invalid where some |pattern - inverse|
    # < 5 DN or the decoded column (row) is beyond the projector; min_contrast = 5 / 255.
    width, height = 912, 1140
    sequence = opencv_graycode_sequence(width, height)
    u, v = surface(width, height)
    gain = np.linspace(2.0, 60.0, CAMERA[1])[np.newaxis, :]  # from hopeless to fine
    frames = render(sequence, u, v, ambient=120.0, gain=gain, sigma=2.0)
    result, _ = decode(sequence, frames, min_contrast=5 / 255)
    values = frames.astype(np.int64)
    expected = np.ones(CAMERA, dtype=bool)
    for axis, (direction, span, first) in enumerate((("v", width, 0), ("h", height, 20))):
        bits = (span - 1).bit_length()
        pattern, inverse = (
            values[first : first + 2 * bits : 2],
            values[first + 1 : first + 2 * bits : 2],
        )
        gray = pattern > inverse
        binary = np.logical_xor.accumulate(gray, axis=0)
        index = (binary * (1 << np.arange(bits - 1, -1, -1))[:, None, None]).sum(axis=0)
        ok = (np.abs(pattern - inverse) >= 5).all(axis=0) & (index < span)
        np.testing.assert_array_equal(getattr(result, f"mask_{direction}"), ok)
        np.testing.assert_array_equal(result.proj_uv[..., axis][ok], index[ok])
        expected &= ok
    np.testing.assert_array_equal(result.mask, expected)
    assert 0.2 < expected.mean() < 0.9  # the test covers both outcomes


# --- round trips ------------------------------------------------------------------------


@pytest.mark.parametrize(("width", "height"), SIZES, ids=lambda s: str(s))
@pytest.mark.parametrize("bits", [None, 6], ids=["per-pixel", "6-bit"])
@pytest.mark.parametrize("inverted", [True, False], ids=["pairs", "thresholded"])
@pytest.mark.parametrize("order", ["msb_first", "lsb_first"])
@pytest.mark.parametrize("code", ["gray", "binary"])
def test_round_trip_under_noise(code, order, inverted, bits, width, height) -> None:
    sequence = code_only(width, height, code, order, inverted, bits)
    u, v = surface(width, height)
    frames = render(sequence, u, v, ambient=20.0, gain=200.0, sigma=3.0)
    result, warned = decode(sequence, frames)
    assert not warned
    for direction, bad in wrong(result, u, v).items():
        mask = getattr(result, f"mask_{direction}")
        assert mask.mean() > 0.97, (direction, mask.mean())
        assert not bad.any(), (direction, int(bad.sum()))
    assert not result.flagged.any()
    if bits is None:  # a word per projector pixel: the column and row indices
        assert result.stripe_v == result.stripe_h == 1.0
    else:
        assert result.stripe_v == width / 64 and result.stripe_h == height / 64
    assert np.isnan(result.phase_v).all() and result.period_v is None


@pytest.mark.parametrize("bits", [None, 6], ids=["per-pixel", "6-bit"])
@pytest.mark.parametrize("inverted", [True, False], ids=["pairs", "thresholded"])
@pytest.mark.parametrize("code", ["gray", "binary"])
def test_low_contrast_over_a_brighter_background(code, inverted, bits) -> None:
    # 40 DN of code over 150 DN of ambient light, sigma 3 DN.
    width, height = SIZES[0]
    sequence = code_only(width, height, code, "msb_first", inverted, bits)
    u, v = surface(width, height)
    frames = render(sequence, u, v, ambient=150.0, gain=40.0, sigma=3.0, seed=1)
    result, warned = decode(sequence, frames)
    assert not warned
    for direction, bad in wrong(result, u, v).items():
        mask = getattr(result, f"mask_{direction}")
        assert mask.mean() > 0.8, (direction, mask.mean())
        share = bad.sum() / mask.sum()
        if code == "gray":  # a mixed edge pixel reads either stripe: never wrong
            assert share == 0.0, (direction, share)
        else:
            assert share <= BINARY_WRONG_MAX[inverted], (direction, share)


@pytest.mark.parametrize("inverted", [True, False], ids=["pairs", "thresholded"])
def test_saturated_pixels_decode_or_are_masked_on_request(inverted) -> None:
    # The right half of the image is so bright that lit frames clip at 255.
    width, height = SIZES[0]
    sequence = code_only(width, height, "gray", "msb_first", inverted)
    u, v = surface(width, height)
    gain = np.where(np.arange(CAMERA[1]) < CAMERA[1] // 2, 150.0, 400.0)[np.newaxis, :]
    frames = render(sequence, u, v, ambient=60.0, gain=gain, sigma=2.0, seed=2)
    assert (frames[:, :, CAMERA[1] // 2 :] == 255).mean() > 0.4
    result, _ = decode(sequence, frames)
    assert result.mask.mean() > 0.95
    assert not any(bad.any() for bad in wrong(result, u, v).values())
    masked, _ = decode(sequence, frames, saturation_level=255)
    assert not masked.mask[:, CAMERA[1] // 2 :].any()
    assert masked.mask[:, : CAMERA[1] // 2].mean() > 0.95


# --- confidence, mask, flags ------------------------------------------------------------


@pytest.mark.parametrize("inverted", [True, False], ids=["pairs", "thresholded"])
def test_confidence_is_the_smallest_bit_contrast_and_sets_the_mask(inverted) -> None:
    width, height = SIZES[0]
    sequence = code_only(width, height, "gray", "lsb_first", inverted, bits=6)
    u, v = surface(width, height)
    gain = np.linspace(0.0, 80.0, CAMERA[1])[np.newaxis, :]  # dark on the left
    frames = render(sequence, u, v, ambient=30.0, gain=gain, sigma=2.0, seed=3)
    values = frames.astype(np.float64)
    white, black = values[-2], values[-1]
    for min_contrast in (0.02, 0.1):
        result, warned = decode(sequence, frames, min_contrast=min_contrast)
        level = min_contrast * 255.0
        for direction in ("v", "h"):
            plan = sequence.plan(direction).code
            contrasts = []
            for normal, inverse in zip(plan.normal, plan.inverse, strict=True):
                if inverted:
                    contrasts.append(np.abs(values[normal] - values[inverse]))
                else:
                    contrasts.append(2.0 * np.abs(values[normal] - 0.5 * (white + black)))
            confidence = np.min(contrasts, axis=0)
            np.testing.assert_array_equal(getattr(result, f"confidence_{direction}"), confidence)
            expected = confidence >= level
            if not inverted:
                expected &= white - black >= level
            np.testing.assert_array_equal(getattr(result, f"mask_{direction}"), expected)
            np.testing.assert_array_equal(
                getattr(result, f"modulation_{direction}"), confidence / 2
            )
        np.testing.assert_array_equal(
            result.confidence, np.minimum(result.confidence_v, result.confidence_h)
        )
        assert not result.mask[:, :4].any()  # no light, no decode
        assert np.isnan(result.proj_uv[~result.mask_v, 0]).all()
        # Thresholded single frames at a few DN of contrast misread a few pixels (2 here),
        # far: the neighbour check flags them. Pairs misread none.
        bad = wrong(result, u, v)
        assert not any((wrong_pixels & ~result.flagged).any() for wrong_pixels in bad.values())
        assert not warned and (not inverted or not any(b.any() for b in bad.values()))
    strict, _ = decode(sequence, frames, min_contrast=0.1)
    loose, _ = decode(sequence, frames, min_contrast=0.02)
    assert (strict.mask <= loose.mask).all() and strict.mask.sum() < loose.mask.sum()
    with pytest.raises(InputError) as info:
        sequence.decode(frames, min_contrast=1.0)
    assert info.value.name == "min_contrast"


@pytest.mark.parametrize("bits", [None, 6, 8], ids=["per-pixel", "6-bit", "8-bit"])
@pytest.mark.parametrize("code", ["gray", "binary"])
def test_swapped_bit_order_is_flagged(code, bits) -> None:
    # Frames projected least significant bit first, described most significant first: every
    # pixel decodes to some code word, but neighbouring stripes no longer follow each other.
    width, height = SIZES[0]
    truth = code_only(width, height, code, "lsb_first", True, bits)
    u, v = surface(width, height)
    frames = render(truth, u, v, ambient=30.0, gain=180.0, sigma=2.0, seed=4)
    right, warned = decode(truth, frames)
    assert not warned and not right.flagged.any()
    described = code_only(width, height, code, "msb_first", True, bits)
    result, warned = decode(described, frames)
    valid = result.mask_v | result.mask_h
    assert valid.mean() > 0.9 and result.flagged[valid].mean() > 0.95
    assert warned and "description" in str(warned[0].message)
    assert result.summary()["flagged_fraction"] > 0.95


def test_depth_edges_misreads_and_unrelated_points() -> None:
    width, height = SIZES[0]
    sequence = code_only(width, height, "gray", "msb_first", True)
    u, v = surface(width, height)
    # A disc 150 px to the right of the surface behind it (parallax), and a few pixels
    # misread: their lowest column bit pairs swapped.
    rows, cols = np.mgrid[0 : CAMERA[0], 0 : CAMERA[1]]
    disc = (rows - 48) ** 2 + (cols - 64) ** 2 < 20**2
    frames = render(sequence, np.where(disc, u + 150.0, u), v, ambient=30.0, gain=180.0, sigma=2.0)
    hit = (rows % 17 == 5) & (cols % 23 == 7)
    for pair in (0, 2, 4):  # the three most significant column bits: far jumps
        frames[pair][hit], frames[pair + 1][hit] = frames[pair + 1][hit], frames[pair][hit].copy()
    result, warned = decode(sequence, frames)
    assert not warned and result.mask.mean() > 0.97
    flagged = result.flagged
    assert (flagged[hit & result.mask]).all()
    assert flagged[~hit].mean() < 0.01  # the disc's edge is not an error
    assert result.repaired == 0
    # Images of unrelated points: the check abstains.
    rng = np.random.default_rng(5)
    u_random = rng.uniform(-0.5, width - 0.6, CAMERA)
    v_random = rng.uniform(-0.5, height - 0.6, CAMERA)
    scattered, warned = decode(
        sequence, render(sequence, u_random, v_random, ambient=30.0, gain=180.0)
    )
    assert not warned and not scattered.flagged.any() and scattered.mask.mean() > 0.95


# --- descriptions -----------------------------------------------------------------------


def test_default_stripes_and_their_centres() -> None:
    width = 912
    sequence = code_only(width, 1140, "binary", "lsb_first", False, bits=6)
    frames = [f for f in sequence.frames if f.direction == "v"]
    assert [f.bit for f in frames] == [6, 5, 4, 3, 2, 1]
    assert {(f.period, f.align) for f in frames} == {(width / 64, "edge")}
    coding = sequence.plan("v").code.coding
    k = np.arange(64)
    first = np.ceil(k * width / 64)
    last = np.ceil((k + 1) * width / 64) - 1
    np.testing.assert_array_equal(coding.cell_centres(k, width), 0.5 * (first + last))
    assert np.isnan(coding.cell_centres(np.array([64, 100]), width)).all()
    # A word per pixel (more words than pixels): pixel j shows j, words past the end are
    # never shown.
    per_pixel = code_only(width, 1140).plan("v").code.coding
    assert per_pixel.period == 1.0
    np.testing.assert_array_equal(per_pixel.cell_centres(np.arange(width), width), np.arange(width))
    assert np.isnan(per_pixel.cell_centres(np.arange(width, 1024), width)).all()


@pytest.mark.parametrize("align", ["centre", "edge"])
def test_a_code_alone_with_its_complementary_frame_halves_the_stripes(align) -> None:
    # A 6-bit Gray code of 18 px periods plus its complementary frame numbers 9 px cells.
    blocks = [
        {"kind": "gray", "direction": d, "period": 18, "bits": bits, "align": align}
        | {"complement": True, "inverted": True}
        for d, bits in (("v", 6), ("h", 7))
    ]
    sequence = PatternSequence.from_dict({"width": 912, "height": 1140, "blocks": blocks})
    u = np.arange(912.0)[np.newaxis, :]  # every projector column, once
    v = np.rint(np.linspace(0, 1139, 912))[np.newaxis, :]
    frames = np.stack(
        [sequence.values(i, u if f.direction == "v" else v) for i, f in enumerate(sequence.frames)]
    )
    result, warned = decode(sequence, frames)
    assert result.mask.all() and not warned
    assert result.stripe_v == result.stripe_h == 9.0
    # A cell of 9 pixels (fewer at the projector's ends) decodes to its middle pixel.
    assert np.abs(result.proj_uv[..., 0] - u).max() == 4.0
    assert np.abs(result.proj_uv[..., 1] - v).max() <= 4.0


def test_single_code_frames_need_white_and_black() -> None:
    with pytest.raises(InputError, match="white and black") as info:
        code_only(912, 1140, inverted=False, uniform=False)
    assert info.value.name == "frames" and "\n" not in str(info.value)
    code_only(912, 1140, inverted=True, uniform=False)  # pairs need no threshold


def test_a_code_alone_beside_a_phase_direction() -> None:
    blocks = [
        {"kind": "phase", "direction": "v", "period": 18, "steps": 4},
        {"kind": "gray", "direction": "v", "period": 18, "bits": 6, "complement": True},
        {"kind": "binary", "direction": "h", "bits": 11, "inverted": True},
        {"kind": "white"},
        {"kind": "black"},
    ]
    sequence = PatternSequence.from_dict({"width": 912, "height": 1140, "blocks": blocks})
    assert sequence.periods("v") == (18.0,) and sequence.periods("h") == ()
    u, v = surface(912, 1140)
    frames = np.empty((len(sequence), *CAMERA))
    h_frames = [i for i, f in enumerate(sequence.frames) if f.direction != "v"]
    for index, frame in enumerate(sequence.frames):
        frames[index] = sequence.values(index, u if frame.direction == "v" else v)
    rendered = render(sequence, u, v, ambient=0.0, gain=255.0, directions=("h",))
    frames[h_frames] = rendered[h_frames] / 255.0
    result, warned = decode(sequence, frames)
    assert not warned and result.mask.mean() > 0.97
    assert result.period_v == 18.0 and result.stripe_v is None and result.stripe_h == 1.0
    assert np.isnan(result.confidence_v).all() and np.isfinite(result.confidence_h).all()
    assert np.isfinite(result.phase_v[result.mask_v]).all() and np.isnan(result.phase_h).all()
    assert not wrong(result, u, v)["h"].any()


def test_sequences_with_phase_frames_have_no_code_only_fields() -> None:
    sequence = default_sequence(40, 30)
    frames = np.stack([sequence.image(i) for i in range(len(sequence))])
    result = sequence.decode(frames)
    assert result.stripe_v is None and result.stripe_h is None
    assert np.isnan(result.confidence).all() and "stripe" not in result.summary()["v"]


def test_device_decoder_refuses_a_code_alone_in_one_line() -> None:
    from virtus.render.jit.decode import decode_on_device, supports

    sequence = opencv_graycode_sequence(40, 30)
    assert not supports(sequence)
    with pytest.raises(VirtusError, match="unsupported.*host") as info:
        decode_on_device(None, sequence, 30, 40)
    assert "\n" not in str(info.value)
