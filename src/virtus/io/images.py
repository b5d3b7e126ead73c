"""Camera image files: reading grey 8/10/12/16-bit PNG, TIFF and BMP, natural sort, PNG writing.

Frames are ``(H, W)`` arrays indexed ``[row, col]``: uint8 for 8-bit images, uint16 for 10,
12 and 16-bit ones (the digital numbers as the camera wrote them, not rescaled). Colour
images whose channels are equal (grey saved as RGB, common for BMP) are read as grey;
true colour images are refused, since fringe decoding needs one intensity per pixel.

PNG encoding dominates the cost of writing; frames are written with OpenCV at a low
compression level on a thread pool (OpenCV releases the GIL while encoding).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from virtus.checks import positive_int
from virtus.errors import InputError

#: Image suffixes read as camera frames.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp")
#: Largest image file read (bytes): a 16-bit 8k x 8k frame is 128 MiB uncompressed.
MAX_IMAGE_BYTES = 256 << 20
#: Largest frame (pixels): 2^28 = 16k x 16k.
MAX_IMAGE_PIXELS = 1 << 28
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


def read_image(path: str | Path) -> np.ndarray:
    """One grey frame: (H, W) uint8 or uint16, unchanged digital numbers."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError("image", "an existing image file", str(path))
    if path.stat().st_size > MAX_IMAGE_BYTES:
        raise InputError(
            str(path), f"an image file of at most {MAX_IMAGE_BYTES >> 20} MiB", "larger"
        )
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(str(path), "a readable PNG, TIFF or BMP image", "unreadable data")
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
        if not cv2.imwrite(str(paths[index]), frames[index], params):
            raise OSError(f"could not write {paths[index]}")

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(write, range(len(frames))))
    return paths
