"""Every coding option: encode -> ideal 8-bit image -> decode, consistency flags, files, errors.

Ground truth is built here: random projector coordinates per camera pixel (plus points
within 0.01 px of every half period) for per-pixel round trips, and smooth coordinate maps
(a tilted, gently curved surface) where neighbours matter (wrong descriptions, repair).
"""

from __future__ import annotations

import json
import warnings
import zlib

import numpy as np
import pytest

from tests import tolerances as tol
from tests.patterns.test_sequence import sample_coordinates
from virtus.errors import InputError
from virtus.patterns import (
    DecodeWarning,
    Frame,
    PatternSequence,
    PhaseCoding,
    default_sequence,
    heterodyne_sequence,
    load_sequence_file,
    phase,
)

TWO_PI = 2.0 * np.pi
EXAMPLES = "examples/sequences"
WIDTH, HEIGHT = 912, 1140


def describe(blocks: list[dict], scale: dict | None = None, **size) -> PatternSequence:
    """A sequence from compact blocks (the description-file form)."""
    data = {"width": size.get("width", WIDTH), "height": size.get("height", HEIGHT)}
    if scale:
        data["scale"] = scale
    return PatternSequence.from_dict({**data, "blocks": blocks})


def both(block: dict) -> list[dict]:
    """The same block for vertical and horizontal fringes."""
    return [block | {"direction": "v"}, block | {"direction": "h"}]


def phase_and_code(period=18.0, steps=18, code=None, phase_extra=None) -> list[dict]:
    """Per direction: a phase set then a code of the same period."""
    out = []
    for direction in ("v", "h"):
        out.append({"kind": "phase", "direction": direction, "period": period, "steps": steps})
        out[-1] |= phase_extra or {}
        out.append({"kind": "gray", "period": period, "bits": 7} | (code or {}))
        out[-1]["direction"] = direction
    return out


def projected(sequence: PatternSequence, u, v, a, b) -> np.ndarray:
    """Camera images ``A + B * value``: each frame's own values at the exact projector
    coordinates (what the projector shows there, 8-bit). Returns float64 ``(F, *u.shape)``."""
    out = np.empty((len(sequence), *np.shape(u)))
    for index, frame in enumerate(sequence.frames):
        out[index] = a + b * sequence.values(index, u if frame.direction == "v" else v)
    return out


def code_edges(sequence: PatternSequence, direction: str) -> np.ndarray:
    """Projector coordinates (px) where a direction's code changes: pixel boundaries."""
    plan = sequence.plans()[direction]
    code = plan.code.coding
    pixels = np.arange(sequence.span(direction), dtype=np.float64)
    order = code.half_index(pixels * sequence.axis_scale(direction)) >> 1
    return np.flatnonzero(np.diff(order)) + 0.5


def round_trip(sequence: PatternSequence, rng, count=6000, band=0.0):
    """Decode 8-bit images of random coordinates; returns (error (N, 2) px, result, periods).

    ``band`` > 0 drops random points closer than that to a code edge of a code without the
    complementary frame (there both ends of a one-period cell have the same phase).
    """
    periods = sorted(
        {f.period / sequence.axis_scale(f.direction) for f in sequence.frames if f.kind == "phase"}
    )
    u, v = sample_coordinates(rng, sequence.width, sequence.height, periods, count)
    if band:
        keep = np.ones(u.size, dtype=bool)
        for direction, x in (("v", u), ("h", v)):
            plan = sequence.plans()[direction]
            if plan.code is not None and not plan.code.coding.complement:
                edges = code_edges(sequence, direction)
                nearest = np.min(np.abs(x[:, None] - edges[None, :]), axis=1)
                keep &= nearest > band
        u, v = u[keep], v[keep]
    a = rng.uniform(10, 60, u.size)
    b = rng.uniform(120, 190, u.size)
    frames = np.rint(projected(sequence, u, v, a, b)).astype(np.uint8)[:, np.newaxis, :]
    result = sequence.decode(frames, neighbour_check=False)
    return result.proj_uv[0] - np.stack([u, v], axis=-1), result, periods


GRAY_VARIANTS = [
    {"align": align, "bit_order": order, "complement": complement, "inverted": inverted}
    for align in ("centre", "edge")
    for order in ("msb_first", "lsb_first")
    for complement in (False, True)
    for inverted in (False, True)
]

CASES = {
    **{
        "gray-{align}-{bit_order}-c{complement:d}-i{inverted:d}".format(**v): phase_and_code(code=v)
        + [{"kind": "white"}, {"kind": "black"}]
        for v in GRAY_VARIANTS
    },
    "binary-code-centre-complement": phase_and_code(code={"kind": "binary", "complement": True}),
    "binary-code-edge-lsb": phase_and_code(
        code={"kind": "binary", "align": "edge", "bit_order": "lsb_first"}
    )
    + [{"kind": "black", "count": 3}],
    "heterodyne": both({"kind": "phase", "periods": [1152 / 64, 1152 / 63, 1152 / 56], "steps": 6})
    + [{"kind": "white"}, {"kind": "black"}],
    "multiwavelength": both({"kind": "phase", "periods": [1152, 144, 18], "steps": 6}),
    **{f"steps-{n}": phase_and_code(steps=n, code={"complement": True}) for n in (3, 4, 7, 18)},
    "period-17.3-complement": phase_and_code(17.3, 9, {"complement": True}),
    "offset-0.7": phase_and_code(phase_extra={"offset": 0.7}, code={"complement": True}),
    "sign-minus": phase_and_code(phase_extra={"sign": -1}, code={"align": "edge"}),
    "ignored-frames": [{"kind": "ignore", "count": 2}]
    + phase_and_code(code={"complement": True})
    + [{"kind": "ignore"}, {"kind": "black", "count": 4}, {"kind": "white", "count": 2}],
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_coding_round_trips_without_order_errors(name: str) -> None:
    sequence = describe(CASES[name])
    no_complement = any(
        p.code is not None and not p.code.coding.complement for p in sequence.plans().values()
    )
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    error, result, periods = round_trip(
        sequence, rng, band=tol.CODE_EDGE_BAND_PX if no_complement else 0.0
    )
    assert result.mask.all()
    rms = np.sqrt(np.mean(error**2, axis=0))
    assert np.all(rms < tol.DECODE_RMS_PX), rms
    assert np.max(np.abs(error)) < periods[0] / 2  # no fringe-order error anywhere
    assert np.max(np.abs(error)) < tol.DECODE_MAX_PX
    assert not result.flagged.any()


def test_row_scale_two_returns_projector_pixels() -> None:
    # A diamond-pixel DMD counting rows in pairs: pattern v = 2 v_p; period 36 pattern units
    # is 18 projector rows, 2280 pattern units need 6 bits of edge-aligned code (64 x 36).
    blocks = phase_and_code(code={"align": "edge", "complement": True})
    blocks[2] |= {"period": 36.0}
    blocks[3] |= {"period": 36.0, "bits": 6}
    sequence = describe(blocks, scale={"h": 2})
    assert sequence.scale == (1.0, 2.0) and sequence.periods("h") == (36.0,)
    rows = np.arange(HEIGHT)
    index = sequence.index_of("phase", "h", step=18)  # shift 2 pi: brightest at phase 0
    np.testing.assert_array_equal(
        sequence.profile(index), np.rint(255 * (0.5 + 0.5 * np.cos(TWO_PI * 2 * rows / 36))) / 255
    )
    error, result, _ = round_trip(sequence, np.random.default_rng(3))
    assert result.mask.all() and result.period_h == 36.0
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < tol.DECODE_RMS_PX)
    assert np.max(np.abs(error)) < tol.DECODE_MAX_PX
    with pytest.raises(InputError) as info:  # 5 bits number 32 x 36 = 1152 < 2280 units
        describe(blocks[:3] + [blocks[3] | {"bits": 5}], scale={"h": 2})
    assert info.value.name == "bits" and ">= 6" in str(info.value)


def test_codes_without_complement_fail_only_at_their_edges() -> None:
    # Both ends of a one-period code cell have the same phase: within the phase noise of a
    # code edge the order is ambiguous (the reason for the complementary frame). Without the
    # band, every order error found lies within it.
    sequence = describe(phase_and_code(code={"align": "edge"}))
    u, v = sample_coordinates(np.random.default_rng(11), WIDTH, HEIGHT, [18.0], 40000)
    frames = np.rint(projected(sequence, u, v, 30.0, 150.0)).astype(np.uint8)[:, None, :]
    result = sequence.decode(frames, neighbour_check=False)
    error = np.abs(result.proj_uv[0] - np.stack([u, v], axis=-1))
    for axis, (direction, x) in enumerate((("v", u), ("h", v))):
        wrong = error[:, axis] >= 9.0
        distance = np.min(np.abs(x[wrong, None] - code_edges(sequence, direction)), axis=1)
        assert np.all(distance < tol.CODE_EDGE_BAND_PX), distance.max()
        assert wrong.mean() < 1e-3


# --- encodings, independent of the code under test --------------------------------------


def test_phase_offset_sign_and_profiles_follow_their_formulas() -> None:
    j = np.arange(WIDTH, dtype=np.float64)
    for profile in ("sinusoidal", "binary", "dithered"):
        sequence = describe(
            phase_and_code(
                period=96.0,
                steps=4,
                code={"complement": True},
                phase_extra={"offset": 0.5, "sign": -1, "profile": profile},
            )
        )
        for n in range(1, 5):
            x = TWO_PI * j / 96.0 + 0.5 - TWO_PI * n / 4
            got = sequence.profile(sequence.index_of("phase", "v", step=n))
            if profile == "sinusoidal":
                np.testing.assert_array_equal(got, np.rint(255 * (0.5 + 0.5 * np.cos(x))) / 255)
            elif profile == "binary":
                np.testing.assert_array_equal(got, (np.cos(x) >= -1e-12).astype(float))
                assert got[:864].mean() == pytest.approx(0.5, abs=1.01 / 96)  # 9 periods
            else:
                assert set(np.unique(got)) <= {0.0, 1.0}
                # Over one 8-pixel dither cell the mean of a constant level is within 1/16
                # of it; the sinusoid changes by at most 8 * (2 pi / 96) / 2 = 0.26 there.
                smooth = np.convolve(got, np.ones(8) / 8, mode="valid")
                target = np.convolve(0.5 + 0.5 * np.cos(x), np.ones(8) / 8, mode="valid")
                assert np.max(np.abs(smooth - target)) < 1 / 16 + 0.26 / 2


def test_edge_aligned_lsb_first_code_and_inverted_pairs() -> None:
    sequence = describe(
        phase_and_code(code={"align": "edge", "bit_order": "lsb_first", "inverted": True})
    )
    j = np.arange(WIDTH)
    gray = np.floor(j / 18.0).astype(np.int64) ^ (np.floor(j / 18.0).astype(np.int64) >> 1)
    frames = [i for i, f in enumerate(sequence.frames) if f.kind == "gray" and f.direction == "v"]
    assert [sequence.frames[i].bit for i in frames] == [b for b in range(7, 0, -1) for _ in "ab"]
    for normal, inverse in zip(frames[::2], frames[1::2], strict=True):
        bit = sequence.frames[normal].bit
        np.testing.assert_array_equal(sequence.profile(normal), (gray >> (7 - bit)) & 1)
        np.testing.assert_array_equal(sequence.profile(inverse), 1 - sequence.profile(normal))
        assert sequence.frames[inverse].inverted


def test_centre_aligned_code_edges_sit_where_the_wrapped_phase_jumps() -> None:
    # Centre: code edges at half periods (wrapped phase jumps); edge: at whole periods.
    for align, first in (("centre", 9.0), ("edge", 18.0)):
        sequence = describe(phase_and_code(code={"align": align}))
        edges = code_edges(sequence, "v")
        np.testing.assert_allclose(edges[:3], first + 18.0 * np.arange(3), atol=tol.GRAY_EDGE_PX)


# --- binary (square-wave) fringes against their harmonic prediction ---------------------


@pytest.mark.parametrize(("steps", "period"), [(4, 24.0), (6, 36.0), (9, 36.0), (18, 72.0)])
def test_binary_fringe_phase_error_matches_harmonic_prediction(steps: int, period: float) -> None:
    # Frame n shows s(j + n P / N) for the projected square wave s (P divisible by 2N, so
    # every frame is the same pixel sequence shifted by whole pixels). With s = sum_k c_k
    # exp(2 pi i k j / P), the estimator sum_n I_n exp(-2 pi i n / N) keeps the harmonics
    # k = 1 mod N: phase error = arg sum_{k = 1 mod N} c_k exp(2 pi i (k - 1) j / P), whose
    # first terms give ((c_{N+1} - c_{N-1}) / c_1) sin(N phi) for a symmetric wave.
    coding = PhaseCoding(period, steps, "binary")
    j = np.arange(WIDTH, dtype=np.float64)
    frames = 20.0 + 200.0 * np.stack([coding.values(n, j) for n in range(1, steps + 1)])
    wrapped, _, _ = coding.wrapped(frames)
    measured = phase.wrap(wrapped - TWO_PI * j / period)
    wave = coding.values(steps, np.arange(int(period), dtype=np.float64))  # shift 2 pi = 0
    c = np.fft.fft(wave) / period
    k = np.arange(int(period))
    aliased = k[(k % steps) == 1]
    phi = TWO_PI * j / period
    predicted = np.angle(
        np.sum(c[aliased, None] * np.exp(1j * (aliased[:, None] - 1) * phi[None, :]), axis=0)
    )
    np.testing.assert_allclose(measured, predicted, atol=tol.PHASE_EXACT_RAD)
    ratio = np.max(np.abs(measured)) / np.max(np.abs(predicted))
    assert abs(ratio - 1.0) < tol.BINARY_FRINGE_PREDICTION_REL
    assert np.max(np.abs(measured)) > 1e-3  # the harmonics are there to be predicted


# --- consistency: wrong descriptions are flagged ----------------------------------------


def surface(shape=(240, 320)) -> tuple[np.ndarray, np.ndarray]:
    """Projector coordinates (px) seen by a camera looking at a tilted, gently curved
    surface: about 1.4 camera px per projector px, so fringes are finely sampled."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = 40.0 + 0.7 * cols + 0.15 * rows + 6.0 * np.sin(rows / 40.0)
    v = 60.0 + 0.7 * rows + 0.1 * cols + 4.0 * np.cos(cols / 50.0)
    return u, v


def lab_blocks(directions=("v", "h"), **code) -> list[dict]:
    """The lab sequence's blocks, with ``code`` options changed for ``directions``."""
    blocks = load_yaml_blocks("lightcrafter_lab.yaml")
    return [b | code if b["kind"] == "gray" and b["direction"] in directions else b for b in blocks]


def load_yaml_blocks(name: str) -> list[dict]:
    import yaml

    with open(f"{EXAMPLES}/{name}") as handle:
        return yaml.safe_load(handle)["blocks"]


def decode_quietly(sequence, frames, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sequence.decode(frames, **options)
    return result, [w for w in caught if issubclass(w.category, DecodeWarning)]


@pytest.mark.parametrize(
    "wrong",
    [(("v",), {"align": "centre"}), (("v", "h"), {"bit_order": "msb_first"})],
    ids=["alignment-swapped", "bit-order-swapped"],
)
def test_lab_frames_under_a_wrong_description_are_flagged(wrong) -> None:
    # (The 5-bit "h" code cannot even be described centre-aligned: it would need 6 bits.)
    truth = describe(lab_blocks())
    u, v = surface()
    frames = np.rint(projected(truth, u, v, 30.0, 180.0)).astype(np.uint8)
    right, warned = decode_quietly(truth, frames)
    assert right.mask.all() and not warned
    assert right.summary()["flagged_fraction"] < tol.FLAGGED_CORRECT_MAX
    error = right.proj_uv - np.stack([u, v], axis=-1)
    assert np.max(np.abs(error)) < tol.DECODE_BINARY_MAX_PX  # a staircase, no order error
    result, warned = decode_quietly(describe(lab_blocks(wrong[0], **wrong[1])), frames)
    valid = result.mask_v | result.mask_h
    share = result.flagged[valid].mean()
    assert share > tol.FLAGGED_WRONG_MIN, share
    assert warned and "description" in str(warned[0].message)


def test_complementary_code_flags_swapped_alignment_per_pixel() -> None:
    # With the complementary frame each pixel carries its own check: no neighbours needed.
    truth = describe(phase_and_code(code={"align": "edge", "complement": True}))
    wrong = describe(phase_and_code(code={"align": "centre", "complement": True}))
    rng = np.random.default_rng(8)
    u, v = sample_coordinates(rng, WIDTH, HEIGHT, [18.0], 6000)
    frames = np.rint(projected(truth, u, v, 20.0, 200.0)).astype(np.uint8)[:, None, :]
    right, _ = decode_quietly(truth, frames, neighbour_check=False)
    assert right.flagged.mean() < tol.FLAGGED_CORRECT_MAX
    result, warned = decode_quietly(wrong, frames, neighbour_check=False)
    assert result.flagged[result.mask_v | result.mask_h].mean() > tol.FLAGGED_WRONG_MIN
    assert warned


def test_repair_fixes_order_jumps_at_plain_code_edges() -> None:
    # A defocused projector (blur sigma 1 camera px) and noisy code frames: the code is
    # misread near its edges, which gives one-period jumps in a thin band; they are flagged
    # by the neighbour check and repaired to the surface's order.
    from scipy import ndimage

    truth = describe(lab_blocks())
    u, v = surface()
    frames = ndimage.gaussian_filter(projected(truth, u, v, 30.0, 180.0), (0, 1, 1))
    codes = [i for i, f in enumerate(truth.frames) if f.kind == "gray"]
    frames[codes] += np.random.default_rng(4).normal(0, 8.0, frames[codes].shape)
    frames = np.clip(np.rint(frames), 0, 255).astype(np.uint8)
    truth_uv = np.stack([u, v], axis=-1)
    inside = (slice(3, -3), slice(3, -3))  # the blur's border
    plain, _ = decode_quietly(truth, frames)
    jumps = (np.abs(plain.proj_uv - truth_uv) >= 9.0).any(axis=-1)
    assert jumps[inside].any()  # the noise does cause jumps ...
    assert np.all(plain.flagged[jumps])  # ... and each is flagged
    fixed, _ = decode_quietly(truth, frames, repair=True)
    assert fixed.repaired >= int(jumps.sum())
    error = np.abs(fixed.proj_uv - truth_uv)[inside][fixed.mask[inside]]
    assert np.max(error) < tol.DECODE_BLURRED_BINARY_MAX_PX
    assert not fixed.flagged.any()


# --- noise, low contrast, strong ambient light ------------------------------------------


NOISY = {
    "default": lambda: default_sequence(),
    "heterodyne": lambda: heterodyne_sequence(),
    "multiwavelength": lambda: load_sequence_file(f"{EXAMPLES}/multiwavelength.yaml")[0],
    "lab": lambda: describe(lab_blocks()),
}


@pytest.mark.parametrize("name", sorted(NOISY))
def test_noise_low_contrast_and_ambient_light_give_no_order_error(name: str) -> None:
    # sigma = 2 DN, pattern amplitude 60 DN (fringe modulation B = 30 DN, 12 % of full
    # scale) on an ambient background of 180 DN: background (210 DN) > modulation.
    sequence = NOISY[name]()
    u, v = surface()
    rng = np.random.default_rng(21)
    frames = projected(sequence, u, v, 180.0, 60.0) + rng.normal(0, 2.0, (len(sequence), *u.shape))
    frames = np.clip(np.rint(frames), 0, 255).astype(np.uint8)
    result, _ = decode_quietly(sequence, frames, repair=name == "lab")
    assert result.mask.mean() > tol.NOISY_VALID_MIN
    error = np.abs(result.proj_uv - np.stack([u, v], axis=-1))
    periods = (sequence.periods("v")[0], sequence.periods("h")[0])
    assert np.all(error[result.mask] < np.array(periods) / 2)  # no order error at all
    assert result.summary()["flagged_fraction"] < tol.FLAGGED_NOISY_MAX
    summary = result.summary()
    # B = 30 DN; 38 DN for square waves (fundamental 2 / pi of the 60 DN amplitude).
    assert 25 < summary["v"]["modulation"]["p50"] < 40
    assert summary["v"]["modulation_rel"]["p50"] == pytest.approx(
        summary["v"]["modulation"]["p50"] / 255
    )


# --- description files ------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CASES))
def test_description_round_trip_is_lossless(name: str) -> None:
    sequence = describe(CASES[name])
    data = json.loads(json.dumps(sequence.to_dict()))
    assert PatternSequence.from_dict(data) == sequence
    assert all(Frame.from_dict(f.to_dict()) == f for f in sequence.frames)


def test_scale_survives_the_round_trip() -> None:
    blocks = phase_and_code(period=36.0, code={"complement": True})
    sequence = describe(blocks, scale={"h": 2})
    back = PatternSequence.from_dict(json.loads(json.dumps(sequence.to_dict())))
    assert back == sequence and back.scale == (1.0, 2.0)


def test_example_files_load() -> None:
    paper, files = load_sequence_file(f"{EXAMPLES}/paper.yaml")
    assert paper == default_sequence() and files is None
    assert load_sequence_file(f"{EXAMPLES}/heterodyne.yaml")[0] == heterodyne_sequence()
    multi = load_sequence_file(f"{EXAMPLES}/multiwavelength.yaml")[0]
    assert multi.periods("h") == (18.0, 144.0, 1152.0) and len(multi) == 38
    lab = load_sequence_file(f"{EXAMPLES}/lightcrafter_lab.yaml")[0]
    assert (lab.width, lab.height, len(lab)) == (912, 570, 52)
    assert sum(f.kind == "black" for f in lab.frames) == 4
    h_code = [f for f in lab.frames if f.kind == "gray" and f.direction == "h"]
    assert [f.bit for f in h_code] == [5, 4, 3, 2, 1] and h_code[0].bits == 5
    assert {f.align for f in lab.frames if f.kind == "gray"} == {"edge"}
    assert {f.profile for f in lab.frames if f.kind == "phase"} == {"binary"}
    assert lab.periods("v") == (18.0,) and lab.periods("h") == (36.0,)


def test_saved_sequence_json_and_file_lists_load(tmp_path) -> None:
    sequence = describe(phase_and_code(code={"align": "edge"}), width=40, height=30)
    path = sequence.save(tmp_path)
    back, files = load_sequence_file(path)
    assert back == sequence and files == [f"{i:03d}.png" for i in range(len(sequence))]
    listed = tmp_path / "listed.json"
    data = {"width": 40, "height": 30, "blocks": CASES["multiwavelength"], "files": ["a.png"]}
    listed.write_text(json.dumps(data))
    with pytest.raises(InputError) as info:
        load_sequence_file(listed)
    assert info.value.name == "files"


# --- bad input --------------------------------------------------------------------------


def phase_v(**extra) -> dict:
    return {"kind": "phase", "direction": "v", "period": 1000, "steps": 3} | extra


@pytest.mark.parametrize(
    ("data", "name"),
    [
        ({"blocks": [{"kind": "sawtooth"}]}, "blocks[0].kind"),
        ({"blocks": [phase_v(steps=2)]}, "blocks[0].steps"),
        ({"blocks": [phase_v(period=0)]}, "period"),
        ({"blocks": [phase_v(period=-3)]}, "period"),
        ({"blocks": [phase_v(period=float("inf"))]}, "period"),
        ({"blocks": [phase_v(period=float("nan"))]}, "period"),
        ({"blocks": [phase_v(profile="triangle")]}, "profile"),
        ({"blocks": [phase_v(sign=2)]}, "sign"),
        ({"blocks": [phase_v(colour="red")]}, "blocks[0]"),
        ({"blocks": [phase_v()], "projector": "dlp"}, "sequence"),
        ({"frames": [{"kind": "white", "level": 1}]}, "frame"),
        ({"blocks": [phase_v()], "scale": {"w": 2}}, "scale"),
        ({"blocks": [phase_v(steps=5000)]}, "blocks[0].steps"),
        ({"blocks": [phase_v(), {"kind": "black", "count": 5000}]}, "blocks[1].count"),
        (
            {"blocks": [phase_v(), {"kind": "gray", "direction": "v", "period": 9, "bits": 25}]},
            "blocks[1].bits",
        ),
        (
            {
                "blocks": [
                    phase_v(),
                    {"kind": "gray", "direction": "v", "period": 9, "bits": 6, "align": "left"},
                ]
            },
            "align",
        ),
        ({"blocks": [phase_v()], "frames": []}, "sequence"),
        ({"blocks": [phase_v()], "version": 9}, "version"),
    ],
)
def test_bad_descriptions_raise_input_error(data, name) -> None:
    with pytest.raises(InputError) as info:
        PatternSequence.from_dict({"width": 912, "height": 1140} | data)
    assert info.value.name == name, str(info.value)


def test_too_few_bits_names_bits_and_the_needed_count() -> None:
    # 5 edge-aligned bits number 32 x 36 = 1152 >= 1140 rows: accepted; centre needs 6.
    good = [phase_v(), {"kind": "phase", "direction": "h", "period": 36, "steps": 18}]
    code = {"kind": "gray", "direction": "h", "period": 36, "bits": 5}
    describe(good + [code | {"align": "edge"}])
    for bad, needed in ((code, 6), (code | {"align": "edge", "bits": 4}, 5)):
        with pytest.raises(InputError) as info:
            describe(good + [bad])
        assert info.value.name == "bits" and f">= {needed}" in str(info.value)


def test_wrong_frame_count_and_malformed_files(tmp_path) -> None:
    sequence = describe(CASES["multiwavelength"])
    with pytest.raises(InputError) as info:
        sequence.decode(np.zeros((len(sequence) - 1, 2, 2), dtype=np.uint8))
    assert info.value.name == "frames"
    cases = {
        "bad.yaml": b"width: [1, 2\n",
        "bad.json": b"{width: 1}",
        "latin.yaml": "width: 912 # caf\xe9\n".encode("latin-1"),
        "list.yaml": b"- 1\n- 2\n",
        "big.yaml": b"#" * (1 << 20) + b"\n",
        "seq.txt": b"{}",
    }
    for file, content in cases.items():
        (tmp_path / file).write_bytes(content)
        with pytest.raises(InputError):
            load_sequence_file(tmp_path / file)
    with pytest.raises(InputError) as info:
        load_sequence_file(tmp_path / "missing.yaml")
    assert info.value.name == "path"


def test_summary_is_json_ready() -> None:
    sequence = describe(CASES["multiwavelength"], width=64, height=48)
    frames = np.zeros((len(sequence), 3, 4), dtype=np.uint8)
    summary = sequence.decode(frames).summary()
    assert json.loads(json.dumps(summary)) == summary
    assert summary["valid_fraction"] == 0.0 and summary["flagged_fraction"] is None
    assert set(summary["v"]["modulation"]) == {"p5", "p50", "p95"}


# --- offset and sign against ground truth; the binary stripe's closed edges -------------


def formula_frames(sequence: PatternSequence, u, v, a, b) -> np.ndarray:
    """Camera images ``A + B * value`` whose phase frames follow the documented formula
    ``0.5 + 0.5 cos(2 pi w / T + offset + sign 2 pi n / N)`` (built here, not by the code
    under test); codes and uniform frames are the sequence's own values (tested above)."""
    out = projected(sequence, u, v, a, b)
    for index, frame in enumerate(sequence.frames):
        if frame.kind != "phase":
            continue
        w = np.asarray(u if frame.direction == "v" else v)
        offset = frame.offset or 0.0
        sign = -1 if frame.sign == -1 else 1
        x = TWO_PI * w / frame.period + offset + sign * TWO_PI * frame.step / frame.steps
        out[index] = a + b * (0.5 + 0.5 * np.cos(x))
    return out


#: sign -1 with an offset (the order of the two matters), and each alone.
OFFSET_SIGN = {
    "offset-0.5-sign-minus": (18.0, 5, {"offset": 0.5, "sign": -1}),
    "offset-0.7-sign-minus-period-17.3": (17.3, 7, {"offset": 0.7, "sign": -1}),
    "offset-minus-2": (18.0, 4, {"offset": -2.0}),
    "sign-minus": (18.0, 6, {"sign": -1}),
}


def offset_sign_sequence(name: str) -> PatternSequence:
    period, steps, extra = OFFSET_SIGN[name]
    blocks = phase_and_code(period, steps, {"complement": True}, phase_extra=extra)
    return describe(blocks + [{"kind": "white"}, {"kind": "black"}])


@pytest.mark.parametrize("name", sorted(OFFSET_SIGN))
def test_offset_and_sign_decode_to_the_true_coordinates(name: str) -> None:
    # Ground truth, not host vs device: applying the offset before the sign instead of
    # after it moves every coordinate by 2 offset T / (2 pi) px (1.4 px for 0.5 rad at T
    # = 18) and passes a comparison of two decoders that share the mistake.
    sequence = offset_sign_sequence(name)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    u, v = sample_coordinates(rng, WIDTH, HEIGHT, [sequence.periods("v")[0]], 4000)
    frames = np.rint(formula_frames(sequence, u, v, 25.0, 190.0)).astype(np.uint8)[:, None, :]
    result = sequence.decode(frames, neighbour_check=False)
    assert result.mask.all()
    error = result.proj_uv[0] - np.stack([u, v], axis=-1)
    assert np.max(np.abs(error)) < tol.DECODE_MAX_PX
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < tol.DECODE_RMS_PX)
    assert not result.flagged.any()


@pytest.mark.parametrize("period", [4, 8, 12, 24, 36, 72])
def test_binary_stripes_are_closed_p_over_2_plus_1_of_p_pixels_on(period: int) -> None:
    # cos x >= 0 on [-pi/2, pi/2] closed: with P/4 a whole number of pixels both edges fall
    # on pixel centres and are lit, so every period has P/2 + 1 lit pixels, symmetric about
    # the stripe's centre (open edges would light P/2 - 1).
    for steps in sorted({n for n in (3, 4, 6, 9, 12, 18) if period % n == 0}):
        coding = PhaseCoding(float(period), steps, "binary")
        j = np.arange(10 * period, dtype=np.float64)
        for step in range(1, steps + 1):
            lit = coding.values(step, j)
            # Shift 2 pi step / N moves the stripe's centre to j = -step P / N (mod P).
            centre = (-step * period // steps) % period
            distance = np.abs((j - centre + period / 2) % period - period / 2)
            np.testing.assert_array_equal(lit, (distance <= period / 4).astype(float))
            counts = lit.reshape(10, period).sum(axis=1)
            assert np.all(counts == period // 2 + 1), (steps, step, counts)
