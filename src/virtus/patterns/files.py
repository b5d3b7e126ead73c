"""Sequence description files: :func:`load_sequence_file` reads one, :func:`sequence_from_dict`
and :func:`sequence_to_dict` convert a description to and from a :class:`PatternSequence`
(behind :meth:`PatternSequence.from_dict` and :meth:`PatternSequence.to_dict`), and
:func:`save_sequence` writes a sequence's frames as PNGs plus ``sequence.json``
(:meth:`PatternSequence.save`). What the fields mean (profiles, offsets, alignment, bit order,
complement): the conventions of :mod:`virtus.patterns.codings`.

Sequence description file (YAML or JSON, one schema)
----------------------------------------------------
Read by :func:`load_sequence_file` (``.yaml``, ``.yml``, ``.json``; at most 1 MB, UTF-8) and
:meth:`PatternSequence.from_dict`; unknown keys anywhere are refused. Top level::

    format: virtus.pattern_sequence   # optional; if present exactly this
    version: 2                        # optional; 1 or 2
    width: 912                        # projector px along u_p (columns), as the rig has them
    height: 1140                      # projector px along v_p (rows), as the rig has them
    scale: {v: 1, h: 1}               # optional pattern units per projector px (below)
    description: free text            # optional
    blocks: [...]                     # compact form, or
    frames: [...]                     # the lossless per-frame form (what to_dict writes), or
    preset: opencv_graycode           # a whole capture named in one line (below)
    files: [000.png, ...]             # optional, one image per frame (importing captures)
    bit_depth: 8                      # optional; only 8

``width`` and ``height`` are the projector's size in the rig's (calibrated) projector px,
which is the size of every image ``virtus patterns`` writes; with ``scale`` they stay so.

``blocks`` (each expands into frames, in this order)::

    {kind: phase, direction: v, period: 18, steps: 18,        # or periods: [..] (one set each)
     profile: sinusoidal, offset: 0.0, sign: 1,                # optional, these defaults
     first_step: 1}         # 0: the frames are numbered 0..N-1 (below)
    {kind: gray, direction: v, period: 18, bits: 6,            # kind gray or binary
     bit_order: msb_first, align: centre, complement: false,   # optional, these defaults
     inverted: false}       # true: each bit (and complement) as a pair: frame, then inverse
    {kind: white, count: 1}                                    # white, black or ignore

Values: ``profile`` ``sinusoidal``, ``binary`` or ``dithered``; ``sign`` ``1`` or ``-1``;
``align`` ``centre`` or ``edge``; ``bit_order`` ``msb_first`` (the frames show bit 1, the
most significant, first) or ``lsb_first`` (least significant first: a 6-bit code's frames
show bits 6, 5, ..., 1); meanings in :mod:`virtus.patterns.codings`.

Phase steps and offsets. Frame ``n`` of a phase set of ``N`` steps shows
``f(Phi + offset + sign 2 pi n / N)``. ``first_step: 1`` (the default) numbers a block's
frames ``n = 1..N``; ``first_step: 0`` numbers them ``n = 0..N-1``, as many labs do (their
first frame has no shift; it is stored as step ``N``, the same image). ``offset`` is in
radians; ``offset_steps: k`` gives it in steps instead (``offset = 2 pi k / N``, any real
``k``; at most one of the two). Both are block keys: the per-frame form (``to_dict``,
``sequence.json``) stores each frame's ``step`` in ``1..N`` and ``offset`` in radians.
E.g. square-wave fringes of period 18 px shifted one pixel a frame, frame ``n = 0..17``
lighting column ``x`` where ``(x + n) mod 18 < 9``::

    {kind: phase, direction: v, period: 18, steps: 18, profile: binary,
     first_step: 0, offset_steps: -4}

Scaled axes (diamond-pixel DMDs). ``scale: {v: s_v, h: s_h}`` (each default 1) sets the
pattern coordinate ``w = s u`` along each axis: periods and code stripes are in pattern
units, decoded ``proj_uv`` in projector px (``w / s``). Projector px ``j`` (image row or
column ``j``) shows the pattern at ``w = s j``, the centre of pattern unit ``s j``. A DLP
LightCrafter 4500 has 1140 diamond-pixel rows at half the column pitch; calibrated with
its rows counted in pairs it is a ``912 x 570`` px projector and its patterns are drawn on
DMD rows: ``height: 570, scale: {h: 2}`` (a 1140 would describe 2280 DMD rows, and a
code sized for 1140 rows is refused as too short). Row ``j`` then stands for the DMD row
pair ``(2j, 2j + 1)`` and shows the value at DMD row ``2j``, the pair's first (even) row,
not the pair's centre ``2j + 0.5``. ``virtus patterns`` writes ``height`` = 570 rows, row
``j`` that value; the 1140-row image the projector takes repeats each row twice
(``image.repeat(2, axis=0)``: DMD rows ``2j`` and ``2j + 1`` both show row ``j``), and
the centre of pair ``j`` then decodes to ``v_p = j``, as virtus's projector model has it
(each value is held over its pair, centred on ``2j + 0.5``). Patterns computed for every
DMD row (DMD row ``r`` showing the value at ``w = r``) put pair ``j``'s centre at
``w = 2j + 0.5``: they decode to ``v_p = j + 0.25``, a silent 0.25 px (about 0.3 mm at
0.3 m) bias in a calibration that puts pair ``j`` at ``v_p = j``.
``examples/sequences/lightcrafter_lab.yaml`` is such a description.

A direction may have a code and no phase frames (a Gray-code-only or binary-only capture):
it decodes to the centre of the code's stripe, the column (row) index for a code per
projector pixel (:mod:`virtus.patterns.codings`). Its ``period`` is the stripe width in
pattern units; left out, it is ``scale * span / 2**bits`` when the code has fewer words
than the axis has pixels (``span`` = ``width`` for ``v``, ``height`` for ``h``; pixel ``j``
shows stripe ``floor(j 2**bits / span)``), else ``scale`` (a word per pixel: pixel ``j``
shows ``j``), and ``align`` defaults to ``edge``. A bit shown without its inverse frame
needs white and black frames (its threshold is ``(white + black) / 2``)::

    {kind: binary, direction: h, bits: 8, bit_order: lsb_first, inverted: true}

``preset: opencv_graycode`` stands for OpenCV's ``structured_light.GrayCodePattern``
capture of a ``width`` x ``height`` projector, exactly the frames it generates
(:func:`~virtus.patterns.catalog.opencv_graycode_sequence`): ``ceil(log2 width)`` column
bits, most significant first, each bit then its inverse, the row bits the same way, then
white and black. Optional ``white_black: true`` (the default: white then black, as
OpenCV's capture sample appends them), ``false`` (none), or ``[black, white]`` for that
order. No ``scale``, ``blocks`` or ``frames`` with it::

    width: 912
    height: 1140
    preset: opencv_graycode           # 2*10 + 2*11 + 2 = 44 frames
    white_black: true                 # optional

``frames`` entries are :meth:`Frame.to_dict` dicts: ``kind`` plus the fields that apply
(``direction``, ``period``, ``step``/``steps``, ``bit``/``bits``, ``profile``, ``offset``,
``sign``, ``align``, ``inverted``; defaults left out), optionally ``index`` (its position)
and ``file``. Counts are bounded: at most :data:`MAX_FRAMES` frames, :data:`MAX_BITS` bits.
Examples: ``examples/sequences/*.yaml``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import finite, positive_int
from virtus.errors import InputError, VirtusError
from virtus.io.jsonio import write_json
from virtus.io.safeio import parse_json, parse_yaml
from virtus.patterns.codings import MAX_BITS, _choice
from virtus.patterns.frames import (
    _CODE_KINDS,
    _UNIFORM_KINDS,
    DIRECTIONS,
    MAX_FRAMES,
    Frame,
    _known_keys,
)
from virtus.patterns.sequence import LEVELS, PatternSequence, _scale_pair

__all__ = [
    "PRESETS",
    "load_sequence_file",
    "save_sequence",
    "sequence_from_dict",
    "sequence_to_dict",
]

_FORMAT = "virtus.pattern_sequence"
_VERSION = 2
_READS_VERSIONS = (1, 2)
_MAX_FILE_BYTES = 1 << 20
_TOP_KEYS = (
    "format",
    "version",
    "width",
    "height",
    "scale",
    "description",
    "bit_depth",
    "blocks",
    "frames",
    "files",
    "preset",
    "white_black",
)
#: ``preset`` values.
PRESETS = ("opencv_graycode",)
_BLOCK_KEYS = {
    "phase": (
        "kind",
        "direction",
        "period",
        "periods",
        "steps",
        "first_step",
        "profile",
        "offset",
        "offset_steps",
        "sign",
    ),
    "code": (
        "kind",
        "direction",
        "period",
        "bits",
        "bit_order",
        "align",
        "complement",
        "inverted",
    ),
    "uniform": ("kind", "count"),
}
_BIT_ORDERS = ("msb_first", "lsb_first")


def sequence_to_dict(sequence: PatternSequence) -> dict[str, Any]:
    """Lossless JSON-ready description of ``sequence``, the per-frame form of the
    description file (periods stay exact float64 values; ``scale`` only when not 1)."""
    out: dict[str, Any] = {
        "format": _FORMAT,
        "version": _VERSION,
        "width": sequence.width,
        "height": sequence.height,
        "bit_depth": 8,
    }
    if sequence.scale != (1.0, 1.0):
        out["scale"] = dict(zip(DIRECTIONS, sequence.scale, strict=True))
    out["frames"] = sequence.describe()
    return out


def sequence_from_dict(
    data: Mapping[str, Any], cls: type[PatternSequence] = PatternSequence
) -> PatternSequence:
    """A sequence (of class ``cls``) from a description (module docstring): the per-frame
    form written by :func:`sequence_to_dict` and :func:`save_sequence`, or the compact
    ``blocks`` form.

    Raises
    ------
    InputError : on unknown keys, a bad value or a sequence that cannot be decoded.
    """
    if not isinstance(data, Mapping):
        raise InputError("data", "a mapping (sequence description)", data)
    _known_keys("sequence", data, _TOP_KEYS)
    if data.get("format", _FORMAT) != _FORMAT:
        raise InputError("format", repr(_FORMAT), data.get("format"))
    if data.get("version", _VERSION) not in _READS_VERSIONS:
        raise InputError("version", f"one of {_READS_VERSIONS}", data.get("version"))
    if data.get("bit_depth", 8) != 8:
        raise InputError("bit_depth", "8", data.get("bit_depth"))
    if "preset" in data:
        return _preset(data, cls)
    if "white_black" in data:
        raise InputError("white_black", "a key of a 'preset' description only", sorted(data))
    if ("frames" in data) == ("blocks" in data):
        raise InputError("sequence", "exactly one of 'frames' and 'blocks'", sorted(data))
    if "blocks" in data:
        frames = _expand_blocks(data["blocks"], data)
    else:
        frames = _frames_from_entries(data["frames"])
    sequence = cls(data.get("width"), data.get("height"), frames, data.get("scale"))  # type: ignore[arg-type]
    _files(data, len(sequence))
    return sequence


def save_sequence(sequence: PatternSequence, directory: str | os.PathLike[str]) -> Path:
    """Write ``sequence``'s frames as 8-bit grayscale PNGs ``000.png, 001.png, ...``
    (``width`` x ``height``) and ``sequence.json`` (:meth:`PatternSequence.to_dict` plus a
    ``file`` entry per frame) into ``directory``, created if needed; files of the same names
    are replaced.

    Returns
    -------
    Path of ``sequence.json``; :func:`sequence_from_dict` and :func:`load_sequence_file`
    read it.
    """
    import cv2  # only needed to write files

    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    digits = max(3, len(str(len(sequence) - 1)))
    data = sequence.to_dict()
    for index, entry in enumerate(data["frames"]):
        name = f"{index:0{digits}d}.png"
        pixels = np.rint(sequence.image(index) * LEVELS).astype(np.uint8)
        if not cv2.imwrite(str(folder / name), pixels):
            raise VirtusError(f"could not write {folder / name}")
        entry["file"] = name
    return write_json(folder / "sequence.json", data)


def _count(name: str, value: Any, total: int) -> int:
    """A user-given frame count, bounded so the running total stays <= MAX_FRAMES."""
    count = positive_int(name, value)
    if total + count > MAX_FRAMES:
        raise InputError(name, f"at most {MAX_FRAMES} frames in all", total + count)
    return count


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise InputError(name, "true or false", value)
    return value


def _preset(data: Mapping[str, Any], cls: type[PatternSequence]) -> PatternSequence:
    """The sequence a ``preset`` description names (module docstring)."""
    from virtus.patterns.catalog import opencv_graycode_sequence  # catalog imports sequence

    _choice("preset", data["preset"], PRESETS)
    clash = sorted(k for k in ("blocks", "frames", "scale") if k in data)
    if clash:
        raise InputError("preset", "no 'blocks', 'frames' or 'scale' beside it", clash)
    built = opencv_graycode_sequence(
        data.get("width"),  # type: ignore[arg-type]
        data.get("height"),  # type: ignore[arg-type]
        white_black=data.get("white_black", True),
    )
    sequence = built if cls is PatternSequence else cls(built.width, built.height, built.frames)
    _files(data, len(sequence))
    return sequence


def _expand_blocks(blocks: Any, data: Mapping[str, Any]) -> tuple[Frame, ...]:
    """Frames from the compact ``blocks`` list (module docstring), bounds checked first
    (``data``: the description, whose size and scale give a code's default period)."""
    if not isinstance(blocks, list) or not blocks:
        raise InputError("blocks", "a non-empty list of block mappings", blocks)
    frames: list[Frame] = []
    for position, block in enumerate(blocks):
        name = f"blocks[{position}]"
        if not isinstance(block, Mapping) or "kind" not in block:
            raise InputError(name, "a mapping with a 'kind' key", block)
        kind = block["kind"]
        if not isinstance(kind, str):
            kind = None  # refused below, not looked up (a list or mapping is unhashable)
        if kind == "phase":
            frames += _phase_block(name, block, len(frames))
        elif kind in _CODE_KINDS:
            frames += _code_block(name, block, len(frames), data)
        elif kind in _UNIFORM_KINDS:
            _known_keys(name, block, _BLOCK_KEYS["uniform"])
            count = _count(f"{name}.count", block.get("count", 1), len(frames))
            frames += [Frame(kind)] * count
        else:
            kinds = ("phase", *_CODE_KINDS, *_UNIFORM_KINDS)
            raise InputError(f"{name}.kind", f"one of {kinds}", block["kind"])
    return tuple(frames)


def _phase_block(name: str, block: Mapping[str, Any], total: int) -> list[Frame]:
    _known_keys(name, block, _BLOCK_KEYS["phase"])
    if ("period" in block) == ("periods" in block):
        raise InputError(name, "exactly one of 'period' and 'periods'", sorted(block))
    periods = [block["period"]] if "period" in block else block["periods"]
    if not isinstance(periods, list) or not periods or len(periods) > MAX_FRAMES:
        raise InputError(f"{name}.periods", f"a list of 1..{MAX_FRAMES} periods", periods)
    steps = positive_int(f"{name}.steps", block.get("steps"), minimum=3)
    _count(f"{name}.steps", steps * len(periods), total)
    extra = {k: block[k] for k in ("profile", "offset", "sign") if k in block}
    if "offset_steps" in block:  # the offset in steps of this block: 2 pi k / N rad
        if "offset" in block:
            raise InputError(name, "at most one of 'offset' and 'offset_steps'", sorted(block))
        extra["offset"] = (
            2.0 * np.pi * finite(f"{name}.offset_steps", block["offset_steps"]) / steps
        )
    first = block.get("first_step", 1)
    if isinstance(first, bool) or not isinstance(first, int | np.integer) or first not in (0, 1):
        raise InputError(f"{name}.first_step", "0 or 1", first)
    # Frame n (first..first + N - 1) shifts by 2 pi n / N: step 0 is step N (a 2 pi shift).
    return [
        Frame(
            "phase", block.get("direction"), period, step=(n - 1) % steps + 1, steps=steps, **extra
        )
        for period in periods
        for n in range(first, first + steps)
    ]


def _code_block(
    name: str, block: Mapping[str, Any], total: int, data: Mapping[str, Any]
) -> list[Frame]:
    _known_keys(name, block, _BLOCK_KEYS["code"])
    bits = positive_int(f"{name}.bits", block.get("bits"))
    if bits > MAX_BITS:
        raise InputError(f"{name}.bits", f"an integer in 1..{MAX_BITS}", bits)
    order = _choice(f"{name}.bit_order", block.get("bit_order", "msb_first"), _BIT_ORDERS)
    complement = _flag(f"{name}.complement", block.get("complement", False))
    inverted = _flag(f"{name}.inverted", block.get("inverted", False))
    polarities = (False, True) if inverted else (False,)
    _count(name, (bits + complement) * len(polarities), total)
    common = {"align": block.get("align"), "period": block.get("period")}
    if "period" not in block:  # a code alone: 2**bits stripes over the axis, from pixel 0
        direction = _choice(f"{name}.direction", block.get("direction"), DIRECTIONS)
        size = "width" if direction == "v" else "height"
        span = positive_int(size, data.get(size))
        scale = _scale_pair(data.get("scale"))[DIRECTIONS.index(direction)]
        stripe = max(1.0, span / 2.0**bits)  # px; a word per pixel when there are enough
        common = {"align": block.get("align", "edge"), "period": scale * stripe}
    kind = block["kind"]
    sequence = range(1, bits + 1) if order == "msb_first" else range(bits, 0, -1)
    frames = [
        Frame(kind, block.get("direction"), bit=b, bits=bits, inverted=p, **common)
        for b in sequence
        for p in polarities
    ]
    if complement:
        frames += [
            Frame(f"{kind}_complement", block.get("direction"), inverted=p, **common)
            for p in polarities
        ]
    return frames


def _frames_from_entries(entries: Any) -> tuple[Frame, ...]:
    """Frames from the per-frame list (each entry's optional ``index`` must be its place)."""
    if not isinstance(entries, list):
        raise InputError("frames", "a list of frame dicts", entries)
    if len(entries) > MAX_FRAMES:
        raise InputError("frames", f"at most {MAX_FRAMES} frames", len(entries))
    for position, entry in enumerate(entries):
        if isinstance(entry, Mapping) and entry.get("index", position) != position:
            raise InputError(f"frames[{position}].index", str(position), entry.get("index"))
    return tuple(Frame.from_dict(entry) for entry in entries)


def _files(data: Mapping[str, Any], count: int) -> list[str] | None:
    """The image list of a description: top-level ``files`` or a ``file`` in every frame
    entry (as :meth:`PatternSequence.save` writes); None when there is none."""
    files = data.get("files")
    if files is None and isinstance(data.get("frames"), list):
        entries = data["frames"]
        if entries and all(isinstance(e, Mapping) and "file" in e for e in entries):
            files = [e["file"] for e in entries]
    if files is None:
        return None
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        raise InputError("files", "a list of file names", files)
    if len(files) != count:
        raise InputError("files", f"{count} file names (one per frame)", len(files))
    first: dict[str, int] = {}
    for index, name in enumerate(files):
        key = os.path.normcase(os.path.normpath(name))  # a.png, ./a.png, x/../a.png: one file
        if key in first:
            raise InputError(
                "files",
                "a different image for every frame",
                f"{name!r} for frames {first[key]} and {index}",
            )
        first[key] = index
    return files


def load_sequence_file(path: str | os.PathLike[str]) -> tuple[PatternSequence, list[str] | None]:
    """Read a sequence description file (module docstring).

    Parameters
    ----------
    path : a ``.yaml``, ``.yml`` or ``.json`` file of at most 1 MB, UTF-8.

    Returns
    -------
    sequence : the :class:`PatternSequence`.
    files : the image file names it lists, one per frame (``files:`` or the per-frame
        ``file`` entries), or None.

    Raises
    ------
    InputError : a missing, oversized, non-UTF-8 or malformed file, or a bad description.
    """
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json"):
        raise InputError("path", "a .yaml, .yml or .json file", str(file))
    if not file.is_file():
        raise InputError("path", "an existing file", str(file))
    size = file.stat().st_size
    if size > _MAX_FILE_BYTES:
        raise InputError("path", f"a file of at most {_MAX_FILE_BYTES} bytes", f"{size} bytes")
    try:
        text = file.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError("path", "UTF-8 text", f"{file}: {error}") from None
    # the guarded parsers: nesting depth bounded before parsing (no RecursionError), YAML
    # aliases bounded, NaN/Infinity, overflowing numbers and duplicate keys refused
    if suffix == ".json":
        data = parse_json(text, f"sequence description {file}")
    else:
        data = parse_yaml(text, f"sequence description {file}")
    sequence = PatternSequence.from_dict(data)
    return sequence, _files(data, len(sequence))
