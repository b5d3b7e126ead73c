"""Every sequence file in ``examples/sequences`` round-trips through ``virtus patterns`` to the
images it describes: each is written by the command and compared pixel by pixel with images
made here, independently of virtus, from the algorithm its source documents (or, where the
source ships its frames, with those frames). Also the file conventions that real benches need:
which DMD row a scaled axis samples, steps numbered from 0, offsets in steps."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from virtus.errors import InputError
from virtus.patterns import PatternSequence, load_sequence_file

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "sequences"
FILES = sorted(EXAMPLES.glob("*.yaml"))


# --- the images each example describes, from its source's algorithm ---------------------


def _stack(profiles: list, width: int, height: int, directions: list[str | None]) -> list:
    """Frames as ``(values, direction, (height, width))``: 1-D ``values`` along columns for
    ``"v"``, along rows for ``"h"``, one value for None (a uniform frame)."""
    return [
        (np.asarray(values, np.float64), direction, (height, width))
        for values, direction in zip(profiles, directions, strict=True)
    ]


def _expand(frame) -> np.ndarray:
    """(height, width) float64 of a frame from :func:`_stack` (or a whole 2-D image)."""
    if isinstance(frame, np.ndarray):
        return frame.astype(np.float64)
    values, direction, shape = frame
    if direction == "v":
        values = values[np.newaxis, :]
    elif direction == "h":
        values = values[:, np.newaxis]
    return np.broadcast_to(values, shape)


def assert_frame_matches(written: np.ndarray, expected: np.ndarray, label: str) -> None:
    """8-bit ``written`` is ``round(expected)``; where ``expected`` is a tie (x.5 to 1e-6,
    e.g. ``255 (0.5 + 0.5 cos)`` where ``cos = 0``) either neighbour is right: float
    rounding of the same formula decides it."""
    assert written.shape == expected.shape, label
    tie = np.abs(np.abs(expected - np.floor(expected)) - 0.5) < 1e-6
    right = (written == np.rint(expected)) | (tie & (np.abs(written - expected) < 0.5 + 1e-6))
    assert right.all(), f"{label}: {np.count_nonzero(~right)} px differ"


def _cosine(x: np.ndarray, period: float, shift: float) -> np.ndarray:
    """``255 (0.5 + 0.5 cos(2 pi x / T + shift))`` before 8-bit rounding."""
    return 255.0 * (0.5 + 0.5 * np.cos(2.0 * np.pi * x / period + shift))


def _gray(k: np.ndarray) -> np.ndarray:
    return k ^ (k >> 1)


def _phase_set_images(width, height, periods, steps):
    """Paper-style phase sets (``0.5 + 0.5 cos(2 pi x / T + 2 pi n / N)``, n = 1..N), vertical
    fringes then horizontal ones, periods in the order given, then white and black."""
    profiles, directions = [], []
    for direction, span in (("v", width), ("h", height)):
        x = np.arange(span, dtype=np.float64)
        for period in periods:
            for n in range(1, steps + 1):
                profiles.append(_cosine(x, period, 2.0 * np.pi * n / steps))
                directions.append(direction)
    profiles += [np.array(255), np.array(0)]
    return _stack(profiles, width, height, [*directions, None, None])


def paper_images() -> np.ndarray:
    """The paper's 52 frames: 18 steps of period 18 px, a 6-bit Gray code of the centred
    fringe order floor(x / 18 + 1/2), most significant bit first, and the complementary frame
    (the least significant bit of the 7-bit code of floor(2 x / 18 + 1)), for vertical then
    horizontal fringes; white, black."""
    profiles, directions = [], []
    for direction, span in (("v", 912), ("h", 1140)):
        x = np.arange(span)
        profiles += [_cosine(x, 18.0, 2.0 * np.pi * n / 18) for n in range(1, 19)]
        order = _gray((2 * x + 18) // 36)  # floor(x / 18 + 1/2)
        profiles += [255 * ((order >> (6 - b)) & 1) for b in range(1, 7)]
        profiles.append(255 * (_gray((2 * x + 18) // 18) & 1))
        directions += [direction] * 25
    profiles += [np.array(255), np.array(0)]
    return _stack(profiles, 912, 1140, [*directions, None, None])


def heterodyne_images() -> np.ndarray:
    """64, 63 and 56 fringes over 1152 px (Towers' periods), 6 steps, then white, black."""
    return _phase_set_images(912, 1140, [1152 / 64, 1152 / 63, 1152 / 56], 6)


def multiwavelength_images() -> np.ndarray:
    """Periods 18, 144 and 1152 px (ratio 8), 6 steps each (frames in the file's order:
    1152, 144, 18), then white, black."""
    return _phase_set_images(912, 1140, [1152.0, 144.0, 18.0], 6)


def opencv_gray(width: int, height: int) -> list[np.ndarray]:
    """OpenCV ``structured_light::GrayCodePattern::generate`` (opencv_contrib, graycodepattern
    .cpp): column bit ``b`` (0 = least significant) of ``col ^ (col >> 1)`` goes to image
    ``2 n - 2 b - 2`` and its inverse to the next one (most significant bit first), then the
    rows likewise; ``n = ceil(log2 width)`` as ``ceil(log(width) / log(2))``."""
    images = []
    for span, along in ((width, "v"), (height, "h")):
        bits = int(np.ceil(np.log(span) / np.log(2.0)))
        index = np.arange(span)
        planes = [None] * (2 * bits)
        for b in range(bits):
            flag = ((index >> b) & 1) ^ ((index >> (b + 1)) & 1)
            planes[2 * bits - 2 * b - 2] = 255 * flag
            planes[2 * bits - 2 * b - 1] = 255 - 255 * flag
        for plane in planes:
            image = np.empty((height, width), np.uint8)
            image[...] = plane[np.newaxis, :] if along == "v" else plane[:, np.newaxis]
            images.append(image)
    return images


def opencv_graycode_images() -> np.ndarray:
    """OpenCV's Gray code of a 912 x 1140 projector, then white and black (its sample)."""
    white, black = np.full((1140, 912), 255, np.uint8), np.zeros((1140, 912), np.uint8)
    return [*opencv_gray(912, 1140), white, black]


def procam_images(height: int = 1140, width: int = 912, step: int = 2) -> np.ndarray:
    """kamino410/procam-calibration ``gen_graycode_imgs.py height width -graycode_step
    step``: OpenCV's Gray code of ((width - 1) // step + 1) x ((height - 1) // step + 1),
    pixel (y, x) showing pattern pixel (y // step, x // step), then white, then black."""
    small = opencv_gray((width - 1) // step + 1, (height - 1) // step + 1)
    rows, cols = np.arange(height) // step, np.arange(width) // step
    images = [pattern[np.ix_(rows, cols)] for pattern in small]
    images += [np.full((height, width), 255, np.uint8), np.zeros((height, width), np.uint8)]
    return images


def elerac_generate(width: int, height: int) -> np.ndarray:
    """elerac/structuredlight ``Gray().generate((width, height))``: ``num = len(bin(width -
    1)) - 2`` frames, frame ``n`` lighting column ``x`` where bit ``num - 1 - n`` of
    ``x ^ (x >> 1)`` is set."""
    bits = len(bin(width - 1)) - 2
    x = np.arange(width)
    return np.stack(
        [
            np.broadcast_to(255 * ((_gray(x) >> (bits - 1 - n)) & 1), (height, width))
            for n in range(bits)
        ]
    ).astype(np.uint8)


def elerac_shipped_frames() -> np.ndarray:
    """The frames elerac/structuredlight ships (``documents/gray.gif``, a copy in
    ``examples/sequences/images``)."""
    from PIL import Image, ImageSequence

    with Image.open(EXAMPLES / "images" / "elerac_structuredlight" / "gray.gif") as gif:
        return np.stack([np.asarray(f.convert("L")) for f in ImageSequence.Iterator(gif)])


def elerac_images() -> np.ndarray:
    """capture_xy.py's order at 320 x 240: the shipped column frames, their inverses
    (``sl.invert``), then the row frames (``sl.transpose(Gray().generate((240, 320)))``)
    and their inverses."""
    columns = elerac_shipped_frames()
    rows = elerac_generate(240, 320).transpose(0, 2, 1)
    return list(np.concatenate([columns, 255 - columns, rows, 255 - rows]))


def lab_bmps() -> np.ndarray:
    """The LightCrafter lab's 912 x 1140 BMPs (kimthyung/3D_Reconstruction_with_Fringe_pattern,
    ``for_calibration/``), in the order its capture shows them: horizontal square waves,
    frame n = 0..17 lighting DMD row r where (r + 8 + 2n) mod 36 < 18 (row pair p = r // 2
    where (p + n + 4) mod 18 < 9); Gray code of floor(r / 36), least significant bit first,
    5 bits; two black frames; vertical square waves lighting column x where
    (x + n + 4) mod 18 < 9; Gray code of floor(x / 18), 6 bits, least significant first; two
    black frames; white. (The lab's own files zero-fill the first few rows and columns of
    frames 0..4 where these wrap around: not describable, left out here.)"""
    r, x = np.arange(1140), np.arange(912)
    profiles = [255 * (((r + 8 + 2 * n) % 36) < 18) for n in range(18)]
    profiles += [255 * ((_gray(r // 36) >> b) & 1) for b in range(5)]
    profiles += [np.array(0)] * 2
    profiles += [255 * (((x + n + 4) % 18) < 9) for n in range(18)]
    profiles += [255 * ((_gray(x // 18) >> b) & 1) for b in range(6)]
    profiles += [np.array(0)] * 2 + [np.array(255)]
    directions = ["h"] * 23 + [None] * 2 + ["v"] * 24 + [None] * 3
    return _stack(profiles, 912, 1140, directions)


#: file name -> the frames it describes (:func:`_stack` triples or whole 2-D images).
REFERENCES = {
    "paper.yaml": paper_images,
    "heterodyne.yaml": heterodyne_images,
    "multiwavelength.yaml": multiwavelength_images,
    "opencv_graycode.yaml": opencv_graycode_images,
    "procam_graycode_step2.yaml": procam_images,
    "elerac_graycode.yaml": elerac_images,
    "lightcrafter_lab.yaml": lab_bmps,
}
#: How the projector takes what ``virtus patterns`` writes: the LightCrafter's 570-row images
#: (rows counted in pairs, ``scale: {h: 2}``) with each row shown on both rows of its pair.
TO_PROJECTOR = {"lightcrafter_lab.yaml": lambda images: images.repeat(2, axis=1)}


def write_with_cli(path: Path, out: Path) -> tuple[np.ndarray, dict]:
    """``virtus patterns --sequence path --out out``: the PNGs it writes, read back, and
    its sequence.json."""
    from virtus.cli import main

    with pytest.raises(SystemExit) as info:
        main(["patterns", "--sequence", str(path), "--out", str(out)])
    assert info.value.code == 0
    data = json.loads((out / "sequence.json").read_text())
    images = [
        cv2.imread(str(out / frame["file"]), cv2.IMREAD_UNCHANGED) for frame in data["frames"]
    ]
    assert all(
        image is not None and image.dtype == np.uint8 and image.ndim == 2 for image in images
    )
    return np.stack(images), data


def test_every_example_has_a_reference() -> None:
    assert FILES and sorted(p.name for p in FILES) == sorted(REFERENCES)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_example_round_trips_through_virtus_patterns(path: Path, tmp_path) -> None:
    sequence, _ = load_sequence_file(path)
    written, data = write_with_cli(path, tmp_path / "out")
    assert written.shape == (len(sequence), sequence.height, sequence.width)
    assert PatternSequence.from_dict(data) == sequence  # the description survives too
    np.testing.assert_array_equal(written, sequence.images())
    projected = TO_PROJECTOR.get(path.name, lambda images: images)(written)
    reference = REFERENCES[path.name]()
    assert len(projected) == len(reference)
    for index, frame in enumerate(reference):  # a frame at a time, to name the one that differs
        assert_frame_matches(projected[index], _expand(frame), f"{path.name} frame {index}")


def test_elerac_shipped_frames_are_their_documented_generator() -> None:
    # The shipped GIF holds Gray().generate((320, 240)) exactly: the row frames the test
    # computes from the same algorithm stand on it.
    np.testing.assert_array_equal(elerac_shipped_frames(), elerac_generate(320, 240))


def test_lightcrafter_example_is_a_912_by_570_projector_on_dmd_rows() -> None:
    lab, _ = load_sequence_file(EXAMPLES / "lightcrafter_lab.yaml")
    assert (lab.width, lab.height, len(lab), lab.scale) == (912, 570, 52, (1.0, 2.0))
    assert [f.kind for f in lab.frames[:1]] + [lab.frames[-1].kind] == ["phase", "white"]
    assert lab.frames[0].direction == "h" and lab.frames[25].direction == "v"
    assert lab.periods("h") == (36.0,) and lab.periods("v") == (18.0,)
    assert sum(f.kind == "black" for f in lab.frames) == 4 and "ignore" not in {
        f.kind for f in lab.frames
    }
    # Decoded projector px are row pairs: exact coordinates in, the same coordinates out.
    rows, cols = np.mgrid[0:60, 0:80].astype(np.float64)
    u, v = 100.0 + 0.7 * cols + 0.1 * rows, 200.0 + 0.7 * rows + 0.05 * cols
    frames = np.stack(
        [
            30.0 + 180.0 * lab.values(i, u if f.direction == "v" else v)
            for i, f in enumerate(lab.frames)
        ]
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        decoded = lab.decode(np.rint(frames).astype(np.uint8))
    good = decoded.mask & ~decoded.flagged
    assert good.mean() > 0.95
    error = decoded.proj_uv[good] - np.stack([u, v], axis=-1)[good]
    assert np.abs(error).max() <= 0.5 + 1e-9  # square waves: the pixel, no order error


# --- the conventions real benches need ----------------------------------------------------

LAB_BLOCKS = [
    {"kind": "phase", "direction": "h", "period": 36, "steps": 18, "profile": "binary"},
    {"kind": "gray", "direction": "h", "period": 36, "bits": 5, "align": "edge"},
    {"kind": "phase", "direction": "v", "period": 18, "steps": 18, "profile": "binary"},
    {"kind": "gray", "direction": "v", "period": 18, "bits": 6, "align": "edge"},
    {"kind": "white"},
    {"kind": "black"},
]


def test_height_with_scale_is_the_projector_px_and_a_dmd_row_count_is_refused() -> None:
    # As files' docstring says: rows counted in pairs are height 570 with scale {h: 2}; 1140
    # with the same scale would be 2280 DMD rows, more than the 5-bit code numbers.
    sequence = PatternSequence.from_dict(
        {"width": 912, "height": 570, "scale": {"h": 2}, "blocks": LAB_BLOCKS}
    )
    assert sequence.images().shape == (len(sequence), 570, 912)
    with pytest.raises(InputError) as info:
        PatternSequence.from_dict(
            {"width": 912, "height": 1140, "scale": {"h": 2}, "blocks": LAB_BLOCKS}
        )
    assert info.value.name == "bits"


@pytest.mark.parametrize("profile", ["sinusoidal", "binary"])
def test_a_scaled_row_samples_the_first_dmd_row_of_its_pair(profile: str) -> None:
    # Row j of a scale-2 axis shows the pattern at DMD row 2j, not 2j + 1 nor the pair centre.
    period, steps = 12.0, 4
    blocks = [
        {"kind": "phase", "direction": "h", "period": period, "steps": steps, "profile": profile},
        {"kind": "gray", "direction": "h", "period": period, "bits": 5, "align": "edge"},
    ]
    sequence = PatternSequence.from_dict(
        {"width": 8, "height": 90, "scale": {"h": 2}, "blocks": blocks}
    )
    r = np.arange(180, dtype=np.float64)  # DMD rows
    for n in range(1, steps + 1):
        cycles = r / period + n / steps
        if profile == "sinusoidal":
            dmd = 255 * (0.5 + 0.5 * np.cos(2 * np.pi * cycles))
        else:  # on where cos >= 0, symmetric about the phase origin
            dmd = 255.0 * (np.abs(np.mod(cycles + 0.5, 1.0) - 0.5) <= 0.25)
        rows = sequence.images()[n - 1][:, :1]
        assert_frame_matches(rows, dmd[0::2, np.newaxis], f"step {n}")
        assert not np.array_equal(rows[:, 0], np.rint(dmd[1::2]))
    code = sequence.images()[steps][:, 0]  # bit 1 of floor(r / 12) at r = 2j
    np.testing.assert_array_equal(code, 255 * ((_gray(np.arange(0, 180, 2) // 12) >> 4) & 1))


def test_patterns_drawn_on_every_dmd_row_decode_a_quarter_pixel_down() -> None:
    # Camera pixels at the centres of DMD row pairs (w = 2j + 0.5), lit by sinusoids drawn
    # for every DMD row: v_p = w / 2 = j + 0.25, the bias the docs state.
    period, steps, height = 64.0, 4, 30  # one period covers the 59 DMD rows: window decode
    sequence = PatternSequence.from_dict(
        {
            "width": 4,
            "height": height,
            "scale": {"h": 2},
            "blocks": [{"kind": "phase", "direction": "h", "period": period, "steps": steps}],
        }
    )
    j = np.arange(4, height - 4, dtype=np.float64)
    w = 2 * j + 0.5
    frames = np.stack(
        [0.5 + 0.5 * np.cos(2 * np.pi * w / period + 2 * np.pi * n / steps) for n in range(1, 5)]
    )[:, :, np.newaxis]
    decoded = sequence.decode(frames)
    np.testing.assert_allclose(decoded.proj_uv[:, 0, 1], j + 0.25, atol=1e-9)


def test_steps_numbered_from_zero_and_offsets_in_steps() -> None:
    # The files docstring's example: frame n = 0..17 lights column x where (x + n) mod 18 < 9.
    block = {
        "kind": "phase",
        "direction": "v",
        "period": 18,
        "steps": 18,
        "profile": "binary",
        "first_step": 0,
        "offset_steps": -4,
    }
    code = {"kind": "gray", "direction": "v", "period": 18, "bits": 6, "align": "edge"}
    sequence = PatternSequence.from_dict({"width": 912, "height": 4, "blocks": [block, code]})
    x = np.arange(912)
    for n in range(18):
        np.testing.assert_array_equal(sequence.images()[n][0], 255 * (((x + n) % 18) < 9))
    assert [f.step for f in sequence.frames[:18]] == [18, *range(1, 18)]
    assert sequence.frames[0].offset == pytest.approx(-8 * np.pi / 18, abs=0)
    back = PatternSequence.from_dict(json.loads(json.dumps(sequence.to_dict())))
    assert back == sequence
    # Sinusoids: frame k of first_step 0 is cos(Phi + 2 pi (k + offset_steps) / N).
    sine = {"kind": "phase", "direction": "v", "period": 40, "steps": 5}  # one fringe: 40 px
    zero = PatternSequence.from_dict(
        {"width": 40, "height": 2, "blocks": [sine | {"first_step": 0, "offset_steps": 1.5}]}
    )
    for k in range(5):
        expected = _cosine(np.arange(40.0), 40.0, 2 * np.pi * (k + 1.5) / 5)
        assert_frame_matches(zero.images()[k][:1], expected[np.newaxis], f"frame {k}")


@pytest.mark.parametrize(
    ("extra", "name"),
    [
        ({"first_step": 2}, "blocks[0].first_step"),
        ({"first_step": True}, "blocks[0].first_step"),
        ({"first_step": 0.0}, "blocks[0].first_step"),
        ({"offset": 0.1, "offset_steps": 1}, "blocks[0]"),
        ({"offset_steps": "one"}, "blocks[0].offset_steps"),
        ({"offset_steps": float("inf")}, "blocks[0].offset_steps"),
    ],
)
def test_bad_step_numbering_and_offsets_are_refused(extra: dict, name: str) -> None:
    block = {"kind": "phase", "direction": "v", "period": 40, "steps": 4} | extra
    with pytest.raises(InputError) as info:
        PatternSequence.from_dict({"width": 40, "height": 2, "blocks": [block]})
    assert info.value.name == name
