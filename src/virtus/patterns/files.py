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
    width: 912                        # projector columns (px)
    height: 1140                      # projector rows (px)
    scale: {v: 1, h: 2}               # optional pattern units per projector px, per direction
    description: free text            # optional
    blocks: [...]                     # compact form, or
    frames: [...]                     # the lossless per-frame form (what to_dict writes), or
    preset: opencv_graycode           # a whole capture named in one line (below)
    files: [000.png, ...]             # optional, one image per frame (importing captures)
    bit_depth: 8                      # optional; only 8

``blocks`` (each expands into frames, in this order)::

    {kind: phase, direction: v, period: 18, steps: 18,        # or periods: [..] (one set each)
     profile: sinusoidal, offset: 0.0, sign: 1}                # optional, these defaults
    {kind: gray, direction: v, period: 18, bits: 6,            # kind gray or binary
     bit_order: msb_first, align: centre, complement: false,   # optional, these defaults
     inverted: false}       # true: each bit (and complement) as a pair: frame, then inverse
    {kind: white, count: 1}                                    # white, black or ignore

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

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive_int
from virtus.errors import InputError, VirtusError
from virtus.io.jsonio import write_json
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
    "phase": ("kind", "direction", "period", "periods", "steps", "profile", "offset", "sign"),
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
            raise InputError(f"{name}.kind", f"one of {kinds}", kind)
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
    return [
        Frame("phase", block.get("direction"), period, step=n, steps=steps, **extra)
        for period in periods
        for n in range(1, steps + 1)
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
    if suffix == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise InputError("path", "valid JSON", f"{file}: {error}") from None
    else:
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise InputError("path", "valid YAML", f"{file}: {error}") from None
    sequence = PatternSequence.from_dict(data)
    return sequence, _files(data, len(sequence))
