"""How fast, and with how little memory, hostile inputs are refused.

Run: ``PYTHONPATH=src python benchmarks/bench_untrusted_inputs.py [--repeats N]``. Writes a
few crafted files (about 1 KB each) into a temporary folder and times the refusal of each
(one :class:`~virtus.errors.InputError` line): ``.npy`` headers declaring 32 GiB, a shape
of 2**64 or a malformed dict (:func:`virtus.io.safeio.load_npy`), an ``.npz`` zip bomb
(:func:`~virtus.io.safeio.load_npz`), images whose header claims 100,000 x 100,000 pixels
or whose data is truncated (:func:`virtus.io.images.read_image`), and a write onto
``/dev/full`` (:func:`virtus.io.runs.atomic_write`). Prints the median and the slowest
of ``N`` refusals (after one warm-up) and the peak memory ``tracemalloc`` traces during one;
the goal is under 10 ms and under 1 MB each.
"""

from __future__ import annotations

import argparse
import statistics
import struct
import tempfile
import time
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from virtus.errors import InputError
from virtus.io.images import read_image
from virtus.io.runs import atomic_write
from virtus.io.safeio import load_npy, load_npz

GOAL_S = 0.010
GOAL_BYTES = 1 << 20


def npy(header: str, data: bytes) -> bytes:
    text = header.encode("latin1")
    text += b" " * (-(10 + len(text) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text + data


def png_claiming(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(bytes(64))) + chunk(b"IEND", b"")
    )  # fmt: skip


def cases(folder: Path) -> dict[str, Callable[[], object]]:
    """Name -> a call that must raise InputError."""
    files = {
        "npy-32GiB.npy": npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (65536, 65536), }", bytes(900)
        ),
        "npy-2pow64.npy": npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551616,), }",
            bytes(8),
        ),
        "npy-malformed.npy": npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4, }", bytes(96)
        ),
        "png-100000.png": png_claiming(100_000, 100_000),
        "bmp-100000.bmp": b"BM" + struct.pack("<IHHI", 1078, 0, 0, 54)
        + struct.pack("<IiiHHIIiiII", 40, 100_000, 100_000, 1, 8, 0, 0, 0, 0, 0, 0)
        + bytes(1024),
    }  # fmt: skip
    for name, data in files.items():
        (folder / name).write_bytes(data)
    valid = folder / "valid.png"
    cv2.imwrite(str(valid), np.random.default_rng(0).integers(0, 65535, (480, 640), np.uint16))
    (folder / "png-truncated.png").write_bytes(valid.read_bytes()[: valid.stat().st_size // 2])
    bomb = folder / "bomb.npz"
    np.savez_compressed(bomb, a=np.zeros((1000, 1000), np.uint8))
    raw = bytearray(bomb.read_bytes())
    at = raw.index(b"PK\x01\x02")
    raw[at + 24 : at + 28] = struct.pack("<I", 0xFFFFFFF0)  # declares 4 GiB
    bomb.write_bytes(bytes(raw))

    calls: dict[str, Callable[[], object]] = {
        name: (lambda p=folder / name: load_npy(p, "array"))
        for name in files
        if name.endswith(".npy")
    }
    calls["npz-zip-bomb.npz"] = lambda: load_npz(bomb, "pose file")
    for name in ("png-100000.png", "bmp-100000.bmp", "png-truncated.png"):
        calls[name] = lambda p=folder / name: read_image(p)
    if Path("/dev/full").exists():
        calls["write-/dev/full"] = lambda: atomic_write("/dev/full", lambda tmp: None)
    return calls


def refuse(call: Callable[[], object]) -> str:
    try:
        call()
    except InputError as error:
        return str(error)
    raise AssertionError("accepted")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    repeats = parser.parse_args().repeats
    with tempfile.TemporaryDirectory() as tmp:
        calls = cases(Path(tmp))
        print(f"refusals of hostile inputs ({repeats} each, after one warm-up)")
        print(f"{'case':<20} {'median ms':>10} {'max ms':>8} {'peak KiB':>9}  message")
        worst_s = worst_bytes = 0.0
        for name, call in calls.items():
            message = refuse(call)
            times = []
            for _ in range(repeats):
                start = time.perf_counter()
                refuse(call)
                times.append(time.perf_counter() - start)
            tracemalloc.start()
            refuse(call)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            worst_s, worst_bytes = max(worst_s, max(times)), max(worst_bytes, peak)
            short = message.replace(tmp + "/", "")
            print(
                f"{name:<20} {statistics.median(times) * 1e3:>10.3f} {max(times) * 1e3:>8.3f} "
                f"{peak / 1024:>9.1f}  {short[:90]}"
            )
        verdict = "met" if worst_s < GOAL_S and worst_bytes < GOAL_BYTES else "NOT met"
        print(
            f"slowest {worst_s * 1e3:.3f} ms, largest peak {worst_bytes / 1024:.1f} KiB: goal "
            f"(< {GOAL_S * 1e3:.0f} ms, < {GOAL_BYTES >> 20} MiB) {verdict}"
        )


if __name__ == "__main__":
    main()
