"""One guarded image reader (virtus.io.images.read_image): the header's size is checked
before anything is decoded, the codecs' own messages are silenced, and every bad image is
one InputError line naming the file."""

from __future__ import annotations

import json
import struct
import tracemalloc
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from virtus.errors import InputError
from virtus.io.images import image_size, read_image

PEAK_BYTES = 1 << 20


def _chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def png_claiming(width: int, height: int) -> bytes:
    """A valid PNG signature and IHDR claiming ``width`` x ``height`` 8-bit grey pixels,
    then a few bytes of image data."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
        + _chunk(b"IDAT", zlib.compress(bytes(64))) + _chunk(b"IEND", b"")
    )  # fmt: skip


def bmp_claiming(width: int, height: int) -> bytes:
    """A BITMAPINFOHEADER claiming ``width`` x ``height`` 8-bit pixels over 1 kB of data."""
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 8, 0, 0, 0, 0, 0, 0)
    return b"BM" + struct.pack("<IHHI", 1078, 0, 0, 54) + info + bytes(1024)


def tiff_claiming(width: int, height: int, order: str = "<") -> bytes:
    """A classic TIFF whose first directory gives ``width`` x ``height`` (LONG tags)."""
    mark = b"II*\x00" if order == "<" else b"MM\x00*"
    tags = struct.pack(order + "HHII", 256, 4, 1, width) + struct.pack(
        order + "HHII", 257, 4, 1, height
    )
    return mark + struct.pack(order + "I", 8) + struct.pack(order + "H", 2) + tags + bytes(4)


def refused(path: Path) -> tuple[str, int]:
    """The one-line message of ``read_image(path)`` and the peak bytes traced refusing it
    (after a warm-up call)."""
    with pytest.raises(InputError):
        read_image(path)
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as error:
            read_image(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(error.value)
    assert "\n" not in message and str(path) in message, message
    return message, peak


HUGE = {
    "png-100000-square": ("huge.png", png_claiming(100_000, 100_000)),
    "png-one-long-side": ("wide.png", png_claiming(200_000, 1)),
    "bmp-100000-square": ("huge.bmp", bmp_claiming(100_000, -100_000)),  # top-down
    "tiff-100000-square": ("huge.tif", tiff_claiming(100_000, 100_000)),
    "tiff-big-endian": ("huge.tiff", tiff_claiming(100_000, 100_000, ">")),
    "png-zero-width": ("zero.png", png_claiming(0, 10)),
}


@pytest.mark.parametrize(("name", "content"), HUGE.values(), ids=HUGE.keys())
def test_a_header_claiming_too_many_pixels_is_refused_before_decoding(
    tmp_path, capfd, name, content
) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    message, peak = refused(path)
    assert peak < PEAK_BYTES
    assert "declared in its header" in message or "at least 1 x 1" in message
    assert "CV_IO_MAX_IMAGE_PIXELS" not in message
    assert capfd.readouterr().err == ""  # nothing from OpenCV


def test_the_header_size_is_what_the_decoder_finds(tmp_path) -> None:
    frame16 = np.arange(48 * 64, dtype=np.uint16).reshape(48, 64)
    frame8 = (frame16 % 251).astype(np.uint8)
    for name, frame in [("a.png", frame16), ("b.png", frame8), ("c.tif", frame16),
                        ("d.tiff", frame8), ("e.bmp", frame8)]:  # fmt: skip
        path = tmp_path / name
        assert cv2.imwrite(str(path), frame)
        assert image_size(path) == (64, 48)
        got = read_image(path)
        assert got.dtype == frame.dtype
        np.testing.assert_array_equal(got, frame)
    big_endian = tmp_path / "f.tif"
    big_endian.write_bytes(tiff_claiming(64, 48, ">"))
    assert image_size(big_endian) == (64, 48)


def _valid_png(tmp_path: Path) -> bytes:
    path = tmp_path / "valid.png"
    noise = np.random.default_rng(0).integers(0, 65535, (48, 64), dtype=np.uint16)
    assert cv2.imwrite(str(path), noise)
    return path.read_bytes()


@pytest.mark.parametrize(
    "damage",
    ["truncated", "truncated-header", "corrupt-data", "bad-ihdr", "not-an-image", "empty",
     "jpeg"],
)  # fmt: skip
def test_damaged_images_are_one_line_naming_the_file(tmp_path, capfd, damage) -> None:
    good = _valid_png(tmp_path)
    data = {
        "truncated": good[: len(good) // 2],
        "truncated-header": good[:20],
        "corrupt-data": good[:60] + b"\xff" * 40 + good[100:],
        "bad-ihdr": good[:12] + b"IHDX" + good[16:],
        "not-an-image": b"not a png",
        "empty": b"",
        "jpeg": b"\xff\xd8\xff\xe0" + bytes(100),
    }[damage]
    path = tmp_path / "frame.png"
    path.write_bytes(data)
    refused(path)
    assert capfd.readouterr().err == ""  # libpng's and OpenCV's own messages silenced


def test_the_codecs_stay_silent_only_while_reading(tmp_path, capfd) -> None:
    path = tmp_path / "frame.png"
    path.write_bytes(_valid_png(tmp_path)[:-30])
    with pytest.raises(InputError):
        read_image(path)
    import os

    os.write(2, b"after\n")  # fd 2 is back
    assert capfd.readouterr().err == "after\n"


def test_import_refuses_a_huge_image_in_one_line(tmp_path, capsys) -> None:
    from virtus.cli import main
    from virtus.geometry.devices import Camera, Rig, default_rig
    from virtus.geometry.optics import Intrinsics
    from virtus.patterns import default_sequence

    rig = default_rig()
    cam = rig.camera.intrinsics
    tiny = Rig(Camera(Intrinsics(cam.fx / 15, cam.fy / 15, 31.5, 23.5, 64, 48)), rig.projector,
               rig.proj2cam)  # fmt: skip
    tiny.save_json(tmp_path / "rig.json")
    (tmp_path / "seq.json").write_text(json.dumps(default_sequence(912, 1140).to_dict()))
    images = tmp_path / "images"
    images.mkdir()
    frame = np.full((48, 64), 1000, np.uint16)
    for index in range(52):
        assert cv2.imwrite(str(images / f"img{index}.png"), frame)
    (images / "img7.png").write_bytes(png_claiming(100_000, 100_000))
    argv = ["import", str(images), "--sequence", str(tmp_path / "seq.json"), "--calibration",
            str(tmp_path / "rig.json"), "--out", str(tmp_path / "out")]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert "img7.png" in lines[0] and "100,000 x 100,000" in lines[0]
