"""Camera image files: reading grey 8/10/12/16-bit PNG, TIFF and BMP, natural sort, PNG writing.

Frames are ``(H, W)`` arrays indexed ``[row, col]``: uint8 for 8-bit images, uint16 for 10,
12 and 16-bit ones (the digital numbers as the camera wrote them, not rescaled). Colour
images whose channels are equal (grey saved as RGB, common for BMP) are read as grey;
true colour images are refused, since fringe decoding needs one intensity per pixel.

Reading is guarded (:func:`read_image`): the size the file's header declares (PNG ``IHDR``,
BMP DIB header, TIFF first directory, :func:`image_size`) is bounded before anything is
decoded, the codecs' own messages are silenced (:func:`quiet_codecs`), and every bad file
is one :class:`~virtus.errors.InputError` line naming it.

PNG encoding dominates the cost of writing; frames are encoded with OpenCV at a low
compression level on a thread pool (OpenCV releases the GIL while encoding) and written by
Python, so that a failed write keeps its errno ("No space left on device") and path.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import struct
import sys
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import IO

import numpy as np

from virtus.checks import positive_int
from virtus.errors import InputError

#: Image suffixes read as camera frames.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp")
#: Largest image file read (bytes): a 16-bit 8k x 8k frame is 128 MiB uncompressed.
MAX_IMAGE_BYTES = 256 << 20
#: Largest frame (pixels): 2^28 = 16k x 16k.
MAX_IMAGE_PIXELS = 1 << 28
#: Longest side of a frame (pixels): 64k, four times the widest camera sensor.
MAX_IMAGE_SIDE = 1 << 16
#: Most tags in a TIFF header's first directory (a camera's TIFF has about 20).
_MAX_TIFF_TAGS = 4096
#: Most image files in a folder read as frames (a pattern sequence has at most 4096 frames,
#: :data:`virtus.patterns.MAX_FRAMES`).
MAX_IMAGES = 4096


def natural_key(name: str) -> list[object]:
    """Sort key that orders digit runs by value: ``img2.png`` before ``img10.png``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def list_images(directory: str | Path) -> list[Path]:
    """The image files (:data:`IMAGE_SUFFIXES`) directly in ``directory``, naturally sorted
    (at most :data:`MAX_IMAGES`)."""
    folder = Path(directory)
    if not folder.is_dir():
        raise InputError("images", "a folder of image files", str(folder))
    files = []
    for path in folder.iterdir():
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            files.append(path)
            if len(files) > MAX_IMAGES:
                raise InputError("images", f"a folder of at most {MAX_IMAGES} images", str(folder))
    if not files:
        raise InputError(
            "images", f"a folder holding {'/'.join(IMAGE_SUFFIXES)} files", str(folder)
        )
    return sorted(files, key=lambda p: natural_key(p.name))


def image_size(path: str | Path) -> tuple[int, int]:
    """``(width, height)`` an image file's header declares, read without decoding anything.

    PNG: the ``IHDR`` chunk (which must come first), and every chunk's length must fit in
    the file (:func:`_check_png_chunks`); BMP: the DIB header; TIFF (classic and
    BigTIFF, either byte order): ``ImageWidth``/``ImageLength`` of the first IFD. The format
    is told by the file's first bytes, not its suffix.

    Raises
    ------
    InputError : ``<path>: expected a PNG, TIFF or BMP image, got ...`` for another format or
        a header too short or malformed to give a size.
    """
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            head = stream.read(32)
            if head.startswith(_PNG_SIGNATURE):
                width_height = _png_size(head, path)
                _check_png_chunks(stream, size, path)
                return width_height
            if head.startswith(b"BM"):
                return _bmp_size(head, path)
            if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
                return _tiff_size(stream, head, size, path)
    except OSError as error:
        raise InputError(str(path), "a readable image file", error.strerror or str(error)) from None
    shown = "an empty file" if not head else f"other data (first bytes {head[:8]!r})"
    raise InputError(str(path), "a PNG, TIFF or BMP image", shown)


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _truncated(path: Path, kind: str) -> InputError:
    return InputError(str(path), f"a readable {kind} image", "a truncated header")


def _png_size(head: bytes, path: Path) -> tuple[int, int]:
    if len(head) < 24:
        raise _truncated(path, "PNG")
    length, chunk, width, height = struct.unpack(">I4sII", head[8:24])
    if chunk != b"IHDR" or length != 13:
        raise InputError(str(path), "a PNG image starting with its IHDR chunk", "a corrupt header")
    return width, height


def _check_png_chunks(stream: IO[bytes], size: int, path: Path) -> None:
    """Refuse a PNG with a chunk whose declared length runs past the end of the file (up to
    ``IEND``): OpenCV's decoder allocates what a chunk declares, gigabytes for a damaged
    100-byte file. Only the 8-byte chunk headers are read (a seek per chunk)."""
    offset = len(_PNG_SIGNATURE)
    while offset + 8 <= size:  # a chunk: length, type, data, CRC (4 bytes)
        stream.seek(offset)
        length, kind = struct.unpack(">I4s", stream.read(8))
        if offset + 12 + length > size:
            raise InputError(
                str(path), "a readable PNG image",
                f"chunk {kind!r} at byte {offset} declaring {length:,} bytes, past the end "
                f"of the {size:,}-byte file",
            )  # fmt: skip
        if kind == b"IEND":
            return
        offset += 12 + length


def _bmp_size(head: bytes, path: Path) -> tuple[int, int]:
    if len(head) < 26:
        raise _truncated(path, "BMP")
    (dib,) = struct.unpack("<I", head[14:18])
    if dib == 12:  # BITMAPCOREHEADER: 16-bit unsigned sizes
        width, height = struct.unpack("<HH", head[18:22])
    elif dib in (16, 40, 52, 56, 64, 108, 124):  # INFO / OS2 v2 / V2-V5: 32-bit signed
        width, height = struct.unpack("<ii", head[18:26])
    else:
        raise InputError(str(path), "a BMP image", f"an unknown {dib}-byte DIB header")
    return abs(width), abs(height)  # a negative height is a top-down bitmap


def _tiff_size(stream: IO[bytes], head: bytes, size: int, path: Path) -> tuple[int, int]:
    order = "<" if head[:2] == b"II" else ">"
    big = head[2:4] in (b"+\x00", b"\x00+")  # BigTIFF: 8-byte offsets and counts
    if len(head) < (16 if big else 8):
        raise _truncated(path, "TIFF")
    offset = struct.unpack(order + ("Q" if big else "I"), head[8:16] if big else head[4:8])[0]
    count_format, entry_size = ("Q", 20) if big else ("H", 12)
    count_size = 8 if big else 2
    if offset + count_size > size:
        raise _truncated(path, "TIFF")
    stream.seek(offset)
    (count,) = struct.unpack(order + count_format, stream.read(count_size))
    if count > _MAX_TIFF_TAGS or offset + count_size + count * entry_size > size:
        raise InputError(str(path), "a TIFF image", f"a corrupt first directory ({count} tags)")
    table = stream.read(count * entry_size)
    found: dict[int, int] = {}
    for index in range(count):
        entry = table[index * entry_size : (index + 1) * entry_size]
        tag, kind = struct.unpack(order + "HH", entry[:4])
        if tag in (256, 257):  # ImageWidth, ImageLength: SHORT, LONG or LONG8
            value = entry[12:] if big else entry[8:]
            codes = {3: "H", 4: "I", 16: "Q"} if big else {3: "H", 4: "I"}
            if kind not in codes:
                raise InputError(str(path), "a TIFF image", f"tag {tag} of type {kind}")
            found[tag] = struct.unpack_from(order + codes[kind], value)[0]
    if 256 not in found or 257 not in found:
        raise InputError(str(path), "a TIFF image", "no ImageWidth/ImageLength in its header")
    return found[256], found[257]


def check_image_size(path: str | Path, width: int, height: int) -> None:
    """Refuse a declared image size of 0 or beyond :data:`MAX_IMAGE_SIDE` /
    :data:`MAX_IMAGE_PIXELS`, before anything is decoded."""
    if width < 1 or height < 1:
        raise InputError(str(path), "an image of at least 1 x 1 pixels", f"{width} x {height}")
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE or width * height > MAX_IMAGE_PIXELS:
        raise InputError(
            str(path),
            f"an image of at most {MAX_IMAGE_PIXELS:,} pixels and {MAX_IMAGE_SIDE:,} per side",
            f"{width:,} x {height:,} declared in its header",
        )


@contextlib.contextmanager
def quiet_codecs() -> Iterator[None]:
    """Silence the image codecs while decoding: OpenCV's log (set to silent, restored
    after) and what libpng/libtiff print on the C ``stderr`` (file descriptor 2 points to
    ``/dev/null``, restored after). Thread-safe: the first reader to enter silences, the
    last to leave restores. virtus reports a failed read itself, as one line."""
    global _quiet_depth, _saved
    import cv2

    with _quiet_lock:
        if _quiet_depth == 0:
            level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
            saved_fd = None
            try:
                sys.stderr.flush()
                saved_fd = os.dup(2)
                null = os.open(os.devnull, os.O_WRONLY)
                try:
                    os.dup2(null, 2)
                finally:
                    os.close(null)
            except (OSError, ValueError, AttributeError):  # no fd 2: nothing to silence
                if saved_fd is not None:
                    os.close(saved_fd)
                saved_fd = None
            _saved = (level, saved_fd)
        _quiet_depth += 1
    try:
        yield
    finally:
        with _quiet_lock:
            _quiet_depth -= 1
            if _quiet_depth == 0:
                level, saved_fd = _saved
                if saved_fd is not None:
                    os.dup2(saved_fd, 2)
                    os.close(saved_fd)
                cv2.utils.logging.setLogLevel(level)


_quiet_lock = threading.Lock()
_quiet_depth = 0
_saved: tuple[int, int | None] = (0, None)


def read_image(path: str | Path) -> np.ndarray:
    """One grey frame: (H, W) uint8 or uint16, unchanged digital numbers.

    The file is checked before it is decoded: a regular file of at most
    :data:`MAX_IMAGE_BYTES`, a PNG, TIFF or BMP header (told by its first bytes) declaring
    at most :data:`MAX_IMAGE_PIXELS` pixels and :data:`MAX_IMAGE_SIDE` per side
    (:func:`image_size`); the codecs' own messages are silenced (:func:`quiet_codecs`).

    Raises
    ------
    InputError : one line naming the file: missing, too large, another format, a header
        declaring too many pixels, truncated or corrupt data, a colour image, a bit depth
        other than 8 or 16.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError("image", "an existing image file", str(path))
    if path.stat().st_size > MAX_IMAGE_BYTES:
        raise InputError(
            str(path), f"an image file of at most {MAX_IMAGE_BYTES >> 20} MiB", "larger"
        )
    width, height = image_size(path)
    check_image_size(path, width, height)
    try:
        with quiet_codecs():
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error as error:
        reason = str(error).strip().splitlines()[-1][:120]
        raise InputError(str(path), "a readable PNG, TIFF or BMP image", reason) from None
    if image is None:
        raise InputError(
            str(path), "a readable PNG, TIFF or BMP image", "truncated or corrupt data"
        )
    if image.ndim == 3:
        if image.shape[2] == 4:
            image = image[..., :3]
        if not all(np.array_equal(image[..., 0], image[..., c]) for c in range(1, image.shape[2])):
            raise InputError(str(path), "a grey image (equal colour channels)", "a colour image")
        image = image[..., 0]
    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise InputError(str(path), "an 8- or 16-bit grey image", f"{image.dtype} {image.shape}")
    if image.size > MAX_IMAGE_PIXELS:
        raise InputError(str(path), f"at most {MAX_IMAGE_PIXELS} pixels", image.size)
    return np.ascontiguousarray(image)


def pool_size(workers: int | None) -> int:
    """Threads for image encoding/decoding: ``workers`` (>= 1), or the number of CPUs."""
    if workers is None:
        return os.cpu_count() or 1
    return positive_int("workers", workers)


def read_images(paths: Sequence[str | Path], workers: int | None = None) -> np.ndarray:
    """Read grey frames into one (F, H, W) array; every frame must have the same size and
    dtype. ``workers``: decoding threads (default: the number of CPUs)."""
    if not paths:
        raise InputError("frames", "at least one image file", 0)
    with ThreadPoolExecutor(max_workers=pool_size(workers)) as pool:
        images = list(pool.map(read_image, paths))
    kinds = sorted({f"{image.shape[1]}x{image.shape[0]} {image.dtype}" for image in images})
    if len(kinds) != 1:
        raise InputError("frames", "images of one size and bit depth", kinds)
    return np.stack(images)


def write_bytes(path: Path, data: bytes | memoryview) -> None:
    """Write ``data`` to a new file ``path``; an ``OSError`` (a full disk, ...) names it."""
    try:
        with open(path, "wb") as handle:
            handle.write(data)
    except OSError as error:
        if error.filename is not None:
            raise
        code = error.errno if error.errno is not None else errno.EIO
        raise type(error)(code, error.strerror or os.strerror(code), str(path)) from error


def frame_name(index: int) -> str:
    """File name of frame ``index`` in a capture's ``frames/`` folder."""
    return f"{index:03d}.png"


def write_frames(
    directory: str | Path,
    frames: np.ndarray,
    *,
    compression: int = 1,
    workers: int | None = None,
) -> list[Path]:
    """Write (F, H, W) uint8/uint16 frames as ``000.png ...`` into ``directory``.

    Parameters
    ----------
    compression : PNG (zlib) level 0-9; 1 is several times faster than OpenCV's default 3
        for a few percent larger files.
    workers : encoding threads (default: the number of CPUs).
    """
    import cv2

    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype not in (np.uint8, np.uint16):
        raise InputError(
            "frames", "a (F, H, W) uint8 or uint16 array", f"{frames.dtype} {frames.shape}"
        )
    if isinstance(compression, bool) or compression not in range(10):
        raise InputError("compression", "a PNG compression level 0-9", compression)
    threads = pool_size(workers)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / frame_name(i) for i in range(len(frames))]
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]

    def write(index: int) -> None:
        # Encoded here and written by Python, so that a failed write keeps its errno (a
        # full disk is "No space left on device", not imwrite's bare False).
        ok, encoded = cv2.imencode(".png", frames[index], params)
        if not ok:
            raise OSError(errno.EIO, "OpenCV could not encode the frame as PNG", str(paths[index]))
        write_bytes(paths[index], encoded.data)

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(write, range(len(frames))))
    return paths
