"""Make tests/data/fixtures/nvcomp_zstd: chunks compressed by nvCOMP on a GPU, which the CPU
test suite reads back with numcodecs and zarr and compares exactly
(tests/data/test_chunkcodecs.py).

Run on a machine with an NVIDIA GPU and ``pip install 'virtus-fpp[gpu]'``
(``nvidia-nvcomp-cu13==6.0.0.12``; ``-cu12`` for CUDA 12)::

    PYTHONPATH=src python scripts/make_nvcomp_fixture.py [--out tests/data/fixtures/nvcomp_zstd]

It compresses a few small deterministic chunks (a stack of 22 fringe frames, uint8; a
float32 phase pair; an int32 order pair; a uint16 object-id map; the phase pair once more
without the byte shuffle) with :class:`virtus.data.chunkcodecs.NvcompZstdFrames`, in pieces
of 4 KiB (so each chunk is several zstd frames, as a 960 x 960 sample's are with the default
64 KiB), checks on the spot that numcodecs decodes every one to the original bytes, and
writes ``<case>.npy`` (the array), ``<case>.zst`` (nvCOMP's stored bytes of the chunk) and
``meta.json`` (the encoder, the piece size, whether a second encode gave the same bytes,
each case's element size for the shuffle and its sizes). About 90 kB in all; a few
seconds. With a CUDA build of torch it also says whether shuffling on the device and on the
host gave the same bytes. ``--cpu-twin`` runs it with the numcodecs twin (no GPU needed).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from virtus.data.chunkcodecs import CpuZstdFrames, NvcompZstdFrames

#: Uncompressed bytes a zstd frame in the fixture (small: several frames a chunk).
PIECE_BYTES = 4096
FIXTURE = Path(__file__).resolve().parents[1] / "tests" / "data" / "fixtures" / "nvcomp_zstd"


def cases(seed: int = 25) -> dict[str, tuple[np.ndarray, int]]:
    """Case name -> (array, byte-shuffle element size): fringe-like, deterministic data."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:24, 0:32]
    steps = np.arange(22)[:, None, None]
    frames = 128 + 100 * np.cos(2 * np.pi * cols / 16 + steps * np.pi / 2)
    frames = np.clip(frames + rng.normal(0, 3, frames.shape), 0, 255).astype(np.uint8)
    phase = np.stack([2 * np.pi * cols / 16, 2 * np.pi * rows / 16]).astype(np.float32)
    phase += rng.normal(0, 1e-3, phase.shape).astype(np.float32)
    order = (phase // (2 * np.pi)).astype(np.int32)
    object_id = (((rows - 12) ** 2 + (cols - 16) ** 2) < 80).astype(np.uint16) * 3
    return {
        "frames": (frames, 1),
        "phase": (phase, 4),
        "order": (order, 4),
        "object_id": (object_id, 2),
        "phase_noshuffle": (phase, 1),
    }


def unshuffle(data: np.ndarray, elementsize: int) -> np.ndarray:
    """The inverse of :func:`virtus.data.chunkcodecs.shuffle_bytes`."""
    if elementsize <= 1:
        return data
    return np.ascontiguousarray(data.reshape(elementsize, -1).T).reshape(-1)


def has_content_size(frame: bytes) -> bool:
    """Whether a zstd frame's header carries the frame content size (RFC 8878 3.1.1.1.1:
    Frame_Content_Size_flag, or Single_Segment_flag); numcodecs 0.16.2-0.16.3 read several
    frames a chunk only without it, 0.16.4 on either way."""
    if frame[:4] != b"\x28\xb5\x2f\xfd":
        raise ValueError(f"not a zstd frame: magic {frame[:4].hex()}")
    descriptor = frame[4]
    return bool(descriptor >> 6) or bool(descriptor & 0x20)


def write_fixture(out: Path, compressor: object) -> bool:
    """Compress :func:`cases` with ``compressor`` (``encode_chunks``, ``name``) and write the
    fixture to ``out``; whether numcodecs decoded every case to its original bytes."""
    from numcodecs import Zstd

    twin = CpuZstdFrames(piece_bytes=PIECE_BYTES)
    table = cases()
    raws = [np.ascontiguousarray(a).reshape(-1).view(np.uint8) for a, _ in table.values()]
    sizes = [size for _, size in table.values()]
    stored = compressor.encode_chunks(raws, sizes)
    again = compressor.encode_chunks(raws, sizes)  # the same bytes for the same input?
    on_cpu = twin.encode_chunks(raws, sizes)
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "format": "virtus.nvcomp_fixture/1",
        "encoder": compressor.name,
        "torch_shuffle_on_device": getattr(compressor, "_torch", None) is not None,
        "piece_bytes": PIECE_BYTES,
        "same_bytes_when_encoded_again": all(
            bytes(a) == bytes(b) for a, b in zip(stored, again, strict=True)
        ),
        "cases": {},
    }
    print(
        f"same bytes when encoded again: {meta['same_bytes_when_encoded_again']}", file=sys.stderr
    )
    ok = True
    for (name, (array, size)), raw, data, cpu in zip(
        table.items(), raws, stored, on_cpu, strict=True
    ):
        decoded = np.frombuffer(Zstd().decode(bytes(data)), np.uint8)
        same = decoded.size == raw.size and np.array_equal(unshuffle(decoded, size), raw)
        ok &= bool(same)
        np.save(out / f"{name}.npy", array)
        (out / f"{name}.zst").write_bytes(bytes(data))
        meta["cases"][name] = {
            "dtype": str(array.dtype),
            "shape": list(array.shape),
            "elementsize": size,
            "raw_bytes": int(raw.size),
            "stored_bytes": len(data),
            "numcodecs_twin_bytes": len(cpu),
            "identical_to_numcodecs_twin": bytes(data) == bytes(cpu),
            "decodes_with_numcodecs": bool(same),
            "first_frame_has_content_size": has_content_size(bytes(data)),
        }
        print(f"{name}: {raw.size} -> {len(data)} bytes (numcodecs twin {len(cpu)}); "
              f"numcodecs decodes it: {same}", file=sys.stderr)  # fmt: skip
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return ok


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=FIXTURE)
    parser.add_argument(
        "--cpu-twin", action="store_true",
        help="compress with the numcodecs twin instead (checks this script without a GPU)",
    )  # fmt: skip
    args = parser.parse_args()
    compressor = CpuZstdFrames(piece_bytes=PIECE_BYTES) if args.cpu_twin else None
    compressor = compressor or NvcompZstdFrames(piece_bytes=PIECE_BYTES)
    ok = write_fixture(args.out, compressor)
    if getattr(compressor, "_torch", None) is not None:  # the host-shuffle path: same bytes?
        table = cases()
        raws = [np.ascontiguousarray(a).reshape(-1).view(np.uint8) for a, _ in table.values()]
        sizes = [size for _, size in table.values()]
        on_device = compressor.encode_chunks(raws, sizes)
        compressor._torch = None
        on_host = compressor.encode_chunks(raws, sizes)
        same = [bytes(a) == bytes(b) for a, b in zip(on_device, on_host, strict=True)]
        print(f"shuffled on the device vs on the host: identical bytes {same}", file=sys.stderr)
    print(f"wrote {args.out} ({compressor.name})", file=sys.stderr)
    if not ok:
        import numcodecs

        sys.exit(
            f"numcodecs {numcodecs.__version__} did not decode the compressed bytes to the "
            "original: see above (several frames a chunk need numcodecs >= 0.16.4)"
        )


if __name__ == "__main__":
    main()
