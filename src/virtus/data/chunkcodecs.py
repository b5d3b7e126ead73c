"""How a store's chunks are compressed: the Zarr codecs of each ``storage.codec``, and who
encodes the bytes -- numcodecs on the CPU, or nvCOMP on a GPU.

**Stored format.** ``storage.codec`` decides the chunk codecs written in each array's
``zarr.json`` (:func:`zarr_compressor`): Blosc (``blosc-zstd``, ``blosc-lz4``,
``blosc-auto``), ``zstd``, ``shuffle-zstd`` (byte shuffle, then zstd) or none. A reader only
needs ``zarr`` and numcodecs (a dependency of ``zarr``), whoever encoded the store.

**Who encodes** (``storage.compress_on``, :data:`COMPRESS_ON`): ``cpu`` -- numcodecs, one
zstd frame per chunk (the bytes every earlier store has); ``gpu`` -- nvCOMP's batched Zstd
(:class:`NvcompZstdFrames`, ``pip install virtus-fpp[gpu]``); ``auto`` -- the GPU when
nvCOMP and a CUDA device work here and the codec is one the GPU writes
(:data:`GPU_CODECS`), else the CPU, saying why (:func:`plan_compression`).

The GPU writes **standard zstd data** (RFC 8878: "compressed data is made of one or more
frames"): nvCOMP's ``RAW`` bitstream kind is the algorithm's own format without nvCOMP's
header, for Zstd a plain zstd frame. nvCOMP's batched API compresses many independent
pieces side by side, one piece per thread block or warp (its header recommends 64 KiB
pieces for speed), so one 48 MB chunk of frames would run on a sliver of the GPU: each
chunk is cut into pieces of :data:`PIECE_BYTES` and its stored bytes are the pieces' frames
one after the other. A zstd decoder reads concatenated frames as the concatenated data --
numcodecs (what zarr-python's ``zstd`` codec calls) from **0.16.4** on: measured here,
0.14.1, 0.15.1, 0.16.0 and 0.16.1 refuse a chunk of several frames ("Destination buffer is
too small"), 0.16.2 and 0.16.3 read it only when the frames carry no content size, 0.16.4 to
0.16.6 always (``tests/data/test_chunkcodecs.py`` checks both kinds, and nvCOMP's own bytes
from ``tests/data/fixtures/nvcomp_zstd``). So a store written on the GPU needs numcodecs >=
:data:`READER_NUMCODECS` to be read (``dataset.json``'s ``encoding`` says so); one written
on the CPU, one frame a chunk, does not. :class:`CpuZstdFrames` writes the GPU layout with
numcodecs: the GPU path's CPU twin, used by the tests.

Measured on one 960 x 960 training sample of ``benchmarks/bench_dataset.py`` (52 frames of
the ideal sensor, float32 labels: 132.7 MB raw), numcodecs zstd level 1, one thread of the
shared 2-core VM (times +-20 %; ``benchmarks/bench_dataset.py --codecs`` prints these rows):

===================================  ========  ======  =======
chunk bytes                          stored    ratio   time
===================================  ========  ======  =======
zstd, one frame a chunk              51.5 MB   2.58    0.135 s
zstd, frames of 256 KiB              51.5 MB   2.58    0.135 s
zstd, frames of 64 KiB               51.7 MB   2.57    0.172 s
byte shuffle, then zstd              35.3 MB   3.76    0.166 s
byte shuffle, zstd frames of 256 KiB 35.3 MB   3.76    0.21 s
byte shuffle, zstd frames of 64 KiB  35.9 MB   3.70    0.28 s
blosc-zstd (shuffle, 1 MiB blocks)   35.5 MB   3.73    0.124 s
===================================  ========  ======  =======

So pieces of 256 KiB cost nothing in size (64 KiB: +0.4 %, shuffled +1.8 %), and the byte
shuffle pays: the real-valued labels shrink by a third (the frames, one byte a pixel, do
not change), 16 MB less to write a sample -- at 2,500 images/s (48 samples/s) 0.8 GB/s
less disk traffic.
Hence ``shuffle-zstd``: Zarr v3 has no shuffle of its own, so the chunk codecs are
``bytes``, ``numcodecs.shuffle`` (elementsize = the dtype's size; one-byte arrays have none)
and ``zstd``; zarr-python reads it through numcodecs (other Zarr implementations may not
know ``numcodecs.shuffle``: use plain ``zstd`` for them). On the GPU the shuffle runs on the
device when a CUDA build of torch is present, else on the host while the chunks are staged
for the copy to the device (:func:`stage_on_host`: 40 ms a sample with the shuffle, 20 ms
without, on the loaded 2-core VM -- against 0.17-0.21 s to compress the sample there).

**Same seed, same arrays -- not the same bytes.** Checksums cover the decoded arrays
(:func:`virtus.data.labels.sample_checksum`), so a GPU-encoded store holds exactly the
arrays of a CPU-encoded one and every reader sees no difference, but its compressed bytes
differ (another encoder, and pieces; whether nvCOMP gives the same bytes for the same input
on every run is checked by ``scripts/make_nvcomp_fixture.py``, not assumed). A store may
mix both (a run resumed with another ``compress_on``): each shard record names its
``encoder``, and ``dataset.json``'s ``encoding`` lists every encoder a record names (shards
written before encoders were recorded name none). Resuming is unaffected: ``compress_on``
is not part of a store's identity.

**Does it pay?** Yes, on the NVIDIA H100 hosts measured (16 cores), where the samples are
labelled on the GPU: a sample then stays on the device from rendering to compression
(:mod:`virtus.data.devicebuffers`) and each worker writes a shard while it renders the next
(``benchmarks/bench_dataset.py --codec shuffle-zstd --compress-on cpu gpu --gpus 1
--workers-per-gpu 8 --samples 720 --shard 4 --no-renderer``; 960 x 960 x 52 frames,
``shuffle-zstd`` level 1, store on the local disk): 1,873-2,758 images/s in the steady part
on the GPU (three runs, two machines; 1,239-1,480 over the whole run, worker start-up
included) against 1,411 on the cores (one run, beside the 1,873; 1,063 over the run);
0.28-0.34 CPU-s a sample against 0.58. ``compress_on`` still defaults to ``cpu``: a store
compressed on the GPU needs numcodecs >= :data:`READER_NUMCODECS` to be read, and its bytes
(not its arrays) depend on nvCOMP's version.

**nvCOMP's encoders, measured** (``benchmarks/bench_dataset.py --samples 1 --codecs``,
nvCOMP 6.0, one NVIDIA H100, one 133 MB sample staged as ``shuffle-zstd`` stages it, all
pieces in one batch; the encode kernel alone, then the copy back). Zstd 10.9 ms a sample in
32 KiB pieces (ratio 3.84), 18.2 ms in 64 KiB (3.93), 46.5 ms in 256 KiB (3.99); four
samples in one batch 8.0 ms a sample (64 KiB). LZ4 7.5-39 ms (2.86-2.88), Snappy 5.9-34 ms
(2.70-2.73), Deflate 9.7-54 ms (3.13-3.16), Bitcomp 0.7-0.8 ms (1.85-1.86), ANS 0.7-0.9 ms
(1.50-1.57), Cascaded 1.9-2.9 ms (1.59) -- only Zstd is read by plain Zarr. Bringing the
frames back costs more than encoding them when nvCOMP's ``.cpu()`` does it (57-142 ms: each
frame into new host memory); one copy of the slots' buffer into a kept page-locked buffer
takes 2.4-5.7 ms (:mod:`virtus.data.hostcopy`). A whole
:meth:`NvcompZstdFrames.encode_chunks` call on a sample: 52-70 ms in 64 KiB pieces (was
106-158 ms); the rest of it, staging the bytes up and joining each chunk's frames, is not
split further. (An earlier survey timed ``.cpu()`` with the kernel and reported 0.4-2.4
GB/s for every algorithm: it measured the copy, not the encoders.)
"""

from __future__ import annotations

import contextlib
import functools
import os
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.data.hostcopy import host_copier
from virtus.errors import BackendUnavailable, InputError, MissingDependency

__all__ = [
    "BLOSC_BLOCK_BYTES",
    "COMPRESS_ON",
    "GPU_CODECS",
    "NVCOMP_REQUIREMENT",
    "PIECE_BYTES",
    "READER_NUMCODECS",
    "STAGING_ALIGN",
    "FAKE_NVCOMP_ENV",
    "CompressionPlan",
    "CpuZstdFrames",
    "NvcompZstdFrames",
    "cpu_encoder_name",
    "encode_samples",
    "encoder_name",
    "encoding_description",
    "make_gpu_compressor",
    "merge_encoding",
    "process_compressor",
    "recorded_encoders",
    "piece_bounds",
    "plan_compression",
    "quiet_numcodecs",
    "regroup",
    "shuffle_bytes",
    "stage_on_host",
    "staging_layout",
    "zarr_compressor",
]

#: Who encodes a store's chunks (module docstring).
COMPRESS_ON = ("auto", "cpu", "gpu")
#: Codecs whose chunks the GPU writes (standard zstd frames; ``shuffle-zstd`` shuffled first).
GPU_CODECS = ("zstd", "shuffle-zstd")
#: Uncompressed bytes per zstd frame on the GPU path (and its CPU twin). On an NVIDIA H100
#: nvCOMP's Zstd kernel took 18.2 ms for a 960 x 960 sample (2,025 pieces) in 64 KiB pieces
#: against 46.5 ms in 256 KiB ones, for 1.5 % more bytes (ratio 3.93 against 3.99; 32 KiB:
#: 10.9 ms but 3.84 and as erratic as 40-139 ms a call): the GPU's time is what the
#: workers share (``benchmarks/bench_dataset.py --samples 1 --codecs``).
PIECE_BYTES = 1 << 16
#: The oldest numcodecs that reads a chunk of several zstd frames (module docstring).
READER_NUMCODECS = "0.16.4"
#: The package that ``compress_on: gpu`` needs (the ``gpu`` extra of pyproject.toml).
NVCOMP_REQUIREMENT = "nvidia-nvcomp-cu13==6.0.0.12"
#: Blosc block size (bytes) of a new store. Blosc's own choice at level 1 is a few tens of
#: kB; 1 MiB blocks compress a 960 x 960 sample about 1.7x faster and 14 % smaller with
#: blosc-zstd (blosc-auto: 1.6x faster, 6 % smaller). A store keeps the block size it was
#: made with (it is in each array's Zarr metadata, which the shard writer follows).
BLOSC_BLOCK_BYTES = 1 << 20
#: Testing hook: ``1`` makes :class:`CpuZstdFrames` stand in for nvCOMP (in worker
#: processes too), so the GPU path -- plan, batch, pieces, records -- runs in CI without a GPU.
FAKE_NVCOMP_ENV = "VIRTUS_FAKE_NVCOMP"
#: zarr-python's warning for ``numcodecs.*`` codecs (``shuffle-zstd``), said once here.
_NUMCODECS_WARNING = "Numcodecs codecs are not in the Zarr version 3 specification"


def zarr_compressor(codec: str, level: int, array: str, itemsize: int = 1) -> Any:
    """The Zarr compressor(s) of array ``array`` (``itemsize`` bytes an element) for a
    store's ``storage.codec`` and ``level`` (:data:`~virtus.data.config.CODECS`; None:
    stored raw). ``blosc-auto`` compresses the frames with blosc-zstd and every label with
    blosc-lz4: zstd makes the frames much smaller than lz4 does, while most real-valued
    labels come out nearly as small with lz4 at a fraction of zstd's time. At 960 x 960,
    level 1, one thread: blosc-zstd 0.19 s and 35 MB a sample, blosc-auto 0.12 s and 39 MB
    (``benchmarks/bench_dataset.py --codecs``); on the 2-core benchmark machine both give
    the same images/s within its noise, so the default stays the smaller blosc-zstd.
    ``shuffle-zstd``: ``[numcodecs.shuffle, zstd]`` for multi-byte arrays (module
    docstring), plain zstd for one-byte ones."""
    from zarr.codecs import BloscCodec, ZstdCodec

    if codec == "none":
        return None
    if codec == "zstd":
        return ZstdCodec(level=level)
    if codec == "shuffle-zstd":
        if itemsize <= 1:
            return ZstdCodec(level=level)
        try:
            from zarr.codecs.numcodecs import Shuffle  # zarr >= 3.1.3
        except ImportError:
            from numcodecs.zarr3 import Shuffle  # older zarr: the same codec, numcodecs' name

        return [Shuffle(elementsize=itemsize), ZstdCodec(level=level)]
    if codec == "blosc-auto":
        codec = "blosc-zstd" if array == "frames" else "blosc-lz4"
    cname = codec.removeprefix("blosc-")
    return BloscCodec(cname=cname, clevel=level, shuffle="shuffle", blocksize=BLOSC_BLOCK_BYTES)


@contextlib.contextmanager
def quiet_numcodecs() -> Iterator[None]:
    """Silence zarr-python's "not in the Zarr v3 specification" warning for the
    ``numcodecs.shuffle`` codec of ``shuffle-zstd`` stores (the module docstring says it);
    a context manager or a decorator."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_NUMCODECS_WARNING)
        yield


def shuffle_bytes(raw: np.ndarray, elementsize: int, out: np.ndarray | None = None) -> np.ndarray:
    """Byte shuffle as numcodecs' ``Shuffle`` does it: byte ``b`` of every element, for
    ``b = 0 .. elementsize - 1``, one after the other.

    Parameters
    ----------
    raw : (n * elementsize,) uint8, C-contiguous (whole elements).
    elementsize : bytes an element (<= 1: no shuffle).
    out : (n * elementsize,) uint8 to write into (None: ``raw`` itself when there is no
        shuffle, else a new array).
    """
    if elementsize > 1 and raw.size % elementsize:
        raise ValueError(f"{raw.size} bytes are not whole elements of {elementsize} bytes")
    if out is None:
        if elementsize <= 1:
            return raw
        out = np.empty_like(raw)
    if elementsize > 1:
        out.reshape(elementsize, -1)[...] = raw.reshape(-1, elementsize).T
    else:
        out[...] = raw
    return out


def piece_bounds(size: int, piece_bytes: int = PIECE_BYTES) -> list[tuple[int, int]]:
    """``(start, stop)`` byte ranges cutting ``size`` bytes into pieces of ``piece_bytes``
    (the last one shorter); one empty piece for ``size == 0``."""
    if piece_bytes < 1:
        raise ValueError(f"piece_bytes must be >= 1, got {piece_bytes}")
    return [(a, min(a + piece_bytes, size)) for a in range(0, max(size, 1), piece_bytes)]


def cpu_encoder_name() -> str:
    """``"numcodecs X.Y.Z"``: who encodes on the CPU."""
    import numcodecs

    return f"numcodecs {numcodecs.__version__}"


def encoder_name(compressor: Any, storage: str = "zarr") -> str:
    """Who encodes a store's shards in this process: the batch ``compressor``'s name
    (``"nvcomp 6.0.0.12"``), else numcodecs (:func:`cpu_encoder_name`); ``"png"`` for PNG
    storage."""
    if storage != "zarr":
        return "png"
    return getattr(compressor, "name", None) or cpu_encoder_name()


class CpuZstdFrames:
    """The GPU path's layout made with numcodecs on the CPU (its twin in the tests): each
    chunk (shuffled when asked) cut into :data:`PIECE_BYTES` pieces, one zstd frame each,
    concatenated -- through the same staging, carving and regrouping as
    :class:`NvcompZstdFrames`.

    Parameters
    ----------
    level : zstd level.
    piece_bytes : uncompressed bytes a frame (default :data:`PIECE_BYTES`).
    """

    def __init__(self, level: int = 1, piece_bytes: int | None = None) -> None:
        from numcodecs import Zstd

        self._zstd = Zstd(level=level)
        self.piece_bytes = piece_bytes or PIECE_BYTES
        self.name = f"{cpu_encoder_name()} (zstd frames of {self.piece_bytes} bytes)"
        #: The torch device whose tensors ``encode_chunks`` reads (None: host arrays only;
        #: the testing hook :data:`FAKE_NVCOMP_ENV` sets ``"cpu"``).
        self.torch_device: str | None = None

    def encode_chunks(
        self, chunks: Sequence[np.ndarray], elementsizes: Sequence[int],
        on_device: Sequence[Any] | None = None,
    ) -> list:  # fmt: skip
        """The stored bytes of each chunk: staged, pieces cut and regrouped exactly as
        :class:`NvcompZstdFrames` does it on the host path, each piece compressed here.

        Parameters
        ----------
        chunks : (n_k,) uint8 arrays, a chunk's bytes each (little endian).
        elementsizes : byte-shuffle element size per chunk (<= 1: no shuffle).
        on_device : the same chunks as torch tensors on :attr:`torch_device` (any dtype of
            the same bytes): compressed instead of ``chunks`` (as the GPU's path does).
        """
        if not chunks:
            return []
        if on_device is not None:
            chunks = [np.asarray(_torch_bytes(t, raw.size).cpu()) for t, raw in
                      zip(on_device, chunks, strict=True)]  # fmt: skip
        starts, pieces, end = staging_layout([raw.size for raw in chunks], self.piece_bytes)
        staging = np.empty(end, np.uint8)
        stage_on_host(chunks, elementsizes, starts, staging)
        frames = [self._zstd.encode(staging[o : o + n]) for o, n in pieces]
        return regroup(frames, [raw.size for raw in chunks], self.piece_bytes)


def _torch_bytes(tensor: Any, size: int) -> Any:
    """A torch tensor's bytes as a flat uint8 tensor of ``size`` bytes (ValueError when it
    has another size: it is not the chunk it stands for)."""
    import torch

    flat = tensor.reshape(-1)
    flat = flat.view(torch.uint8)  # bool and every other dtype: the same bytes
    if flat.numel() != size:
        raise ValueError(f"a device chunk of {flat.numel()} bytes for a chunk of {size}")
    return flat


def regroup(frames: Sequence[Any], sizes: Sequence[int], piece_bytes: int) -> list[bytes]:
    """Each chunk's stored bytes: its pieces' frames (``frames`` in chunk order, as
    :func:`staging_layout` lists the pieces) one after the other."""
    out, first = [], 0
    for size in sizes:
        count = len(piece_bounds(size, piece_bytes))
        out.append(b"".join(memoryview(f) for f in frames[first : first + count]))
        first += count
    if first != len(frames):
        raise ValueError(f"{len(frames)} frames for {first} pieces")
    return out


#: Byte alignment of every chunk in a staging buffer (nvCOMP's Zstd needs 4; 16 is what its
#: documentation advises when in doubt). Pieces inside a chunk start at multiples of the
#: piece size, itself a multiple of this.
STAGING_ALIGN = 16


def staging_layout(
    sizes: Sequence[int], piece_bytes: int
) -> tuple[list[int], list[tuple[int, int]], int]:
    """Where chunks of ``sizes`` bytes sit in one staging buffer: each chunk's start
    (aligned to :data:`STAGING_ALIGN`), every piece's ``(offset, length)`` in chunk order,
    and the buffer's length."""
    if piece_bytes % STAGING_ALIGN:
        raise ValueError(f"piece_bytes must be a multiple of {STAGING_ALIGN}, got {piece_bytes}")
    starts, pieces, end = [], [], 0
    for size in sizes:
        start = -(-end // STAGING_ALIGN) * STAGING_ALIGN
        starts.append(start)
        pieces += [(start + a, b - a) for a, b in piece_bounds(size, piece_bytes)]
        end = start + size
    return starts, pieces, end


def stage_on_host(
    chunks: Sequence[np.ndarray], elementsizes: Sequence[int], starts: Sequence[int],
    staging: np.ndarray,
) -> None:  # fmt: skip
    """Copy every chunk, byte-shuffled where its element size is > 1, to its ``start`` in
    ``staging`` (uint8, at least the layout's length: :func:`staging_layout`)."""
    for raw, size, start in zip(chunks, elementsizes, starts, strict=True):
        shuffle_bytes(raw, size, out=staging[start : start + raw.size])


class NvcompZstdFrames:
    """nvCOMP's batched Zstd on this process's CUDA device (``RAW`` bitstream: standard zstd
    frames): all pieces of all chunks of one call compressed in one batch.

    The chunks come from host memory (a shard buffer), or from the device where the samples
    were made (``on_device``: :mod:`virtus.data.devicebuffers`). They are gathered into one
    staging buffer on the device (:func:`staging_layout`: chunk starts aligned, pieces
    carved from it by offset): with a CUDA build of torch each chunk is copied up (unless it
    is there already) and byte-shuffled on the device, else shuffled into a host staging
    buffer (:func:`stage_on_host`) that is copied up at once. The frames are written into
    slots of a device buffer and come back in one copy into a page-locked host buffer
    (:meth:`_frames`). These buffers are kept per thread and grow as needed: each about as
    large as the uncompressed bytes of the largest call (a shard's, in a worker), on the
    device and (page-locked) on the host. nvCOMP's
    Zstd has no level setting: ``level`` in ``zarr.json`` is the CPU's. An nvCOMP
    ``Codec`` must not be used by two threads at once (its manager and scratch buffers), so
    each thread that encodes makes its own (a pipelined run encodes on two).

    Raises
    ------
    MissingDependency : nvCOMP's Python package is not installed.
    BackendUnavailable : it is, but no CUDA device works with it here.
    """

    def __init__(self, piece_bytes: int | None = None) -> None:
        import threading

        self.piece_bytes = piece_bytes or PIECE_BYTES
        staging_layout([1], self.piece_bytes)  # a piece size the staging can align
        self._nvcomp = import_nvcomp()
        self._local = threading.local()
        self._codec()  # fails here, not in the first shard, without a usable device
        self.name = f"nvcomp {self._nvcomp.__version__}"

    @functools.cached_property
    def _torch_staging(self) -> tuple[Any, str | None]:
        """torch and the device where the chunks are staged (a CUDA build of torch and
        ``"cuda"``; (None, None) without one: staged on the host), found on first use:
        importing torch takes seconds (4-5 s on an H100 host), and the compressor that
        :func:`plan_compression` makes only to see that nvCOMP works never encodes."""
        return _staging_torch()

    @property
    def _torch(self) -> Any:
        return self._torch_staging[0]

    @property
    def torch_device(self) -> str | None:
        """The torch device whose tensors :meth:`encode_chunks` reads (None: host only)."""
        return self._torch_staging[1]

    def _codec(self) -> Any:
        """This thread's nvCOMP Zstd codec (RAW bitstream), made on first use."""
        codec = getattr(self._local, "codec", None)
        if codec is None:
            try:
                codec = self._nvcomp.Codec(  # RAW: one input buffer, one frame
                    algorithm="Zstd",
                    bitstream_kind=self._nvcomp.BitstreamKind.RAW,
                    uncomp_chunk_size=self.piece_bytes,  # the largest buffer it is given
                )
            except Exception as error:  # nvCOMP raises RuntimeError kinds without a device
                raise BackendUnavailable(
                    f"storage.compress_on gpu: nvCOMP finds no usable CUDA device ({error}); "
                    "use compress_on: cpu or auto"
                ) from None
            bound = codec.get_max_comp_buffer_size(
                self._nvcomp.as_array(np.zeros(self.piece_bytes, np.uint8)).cuda()
            )  # the most bytes a piece's frame may take: each frame's slot, aligned
            self._local.slot = -(-bound // STAGING_ALIGN) * STAGING_ALIGN
            self._local.copier = host_copier()  # nvCOMP has made the context current
            self._local.codec = codec
        return codec

    def _staging(self, kind: str, length: int, make: Any) -> Any:
        """This thread's staging buffer ``kind`` of at least ``length`` bytes (kept)."""
        buffer = getattr(self._local, kind, None)
        if buffer is None or len(buffer) < length:
            buffer = None  # the old one is freed first
            buffer = make(max(length, 1))
            setattr(self._local, kind, buffer)
        return buffer

    def _on_device(
        self, chunks: Sequence[np.ndarray], sizes: Sequence[int], starts: list, end: int,
        on_device: Sequence[Any] | None,
    ) -> Any:  # fmt: skip
        """The chunks, shuffled where asked, at ``starts`` of one device buffer (copied up
        from the host, or from ``on_device`` where the device has them already)."""
        torch = self._torch
        if torch is None:
            staging = self._staging("host", end, lambda n: np.empty(n, np.uint8))
            stage_on_host(chunks, sizes, starts, staging)
            return self._nvcomp.as_array(staging[:end]).cuda()
        staging = self._staging(
            "device", end, lambda n: torch.empty(n, dtype=torch.uint8, device=self.torch_device)
        )
        for k, (raw, size, start) in enumerate(zip(chunks, sizes, starts, strict=True)):
            if on_device is None:
                source = torch.from_numpy(raw).to(self.torch_device)
            else:
                source = _torch_bytes(on_device[k], raw.size)
            target = staging[start : start + raw.size]
            if size > 1:
                target.view(size, -1).copy_(source.view(-1, size).t())
            else:
                target.copy_(source)
        if self.torch_device == "cuda":
            torch.cuda.current_stream().synchronize()  # nvCOMP works on its own stream
        return staging[:end]

    def encode_chunks(
        self, chunks: Sequence[np.ndarray], elementsizes: Sequence[int],
        on_device: Sequence[Any] | None = None,
    ) -> list:  # fmt: skip
        """The stored bytes of each chunk (as :meth:`CpuZstdFrames.encode_chunks`);
        ``on_device``: the same chunks as CUDA tensors (needs :attr:`torch_device`), read
        there instead of copying ``chunks`` up."""
        if not chunks:
            return []
        if on_device is not None and self._torch is None:
            raise ValueError("device chunks need torch where the chunks are staged")
        starts, pieces, end = staging_layout([raw.size for raw in chunks], self.piece_bytes)
        self._codec()  # this thread's codec, frame slot size and copier
        device = self._on_device(chunks, elementsizes, starts, end, on_device)
        lengths = [n for _, n in pieces]
        batch = self._nvcomp.as_arrays(device, [o for o, _ in pieces], lengths)
        frames = self._frames(batch, lengths)
        out = regroup(frames, [raw.size for raw in chunks], self.piece_bytes)
        del batch, device  # the staging buffer is free for the next call once encoded
        return out

    def _frames(self, batch: Any, lengths: list[int]) -> list:
        """Each piece's zstd frame, on the host (views valid until this thread's next call).

        nvCOMP writes every frame into its slot of one kept device buffer, which is copied
        back at once into a kept page-locked buffer (:mod:`virtus.data.hostcopy`: 2.4 ms a
        sample, against 47-58 ms for nvCOMP's copy of each frame into new memory); where
        the CUDA driver cannot make that copy, nvCOMP copies the frames itself."""
        nvcomp, codec, slot = self._nvcomp, self._codec(), self._local.slot
        count = len(lengths)
        target = self._staging(
            "slots",
            slot * count,
            lambda n: _Sized(nvcomp.as_array(np.empty(n, np.uint8)).cuda(), n),
        ).array
        slots = nvcomp.as_arrays(target, [k * slot for k in range(count)], [slot] * count)
        config = codec.compression_config(lengths)  # no per-call configuration in encode
        encoded = codec.encode(batch, out=slots, compression_config=config)
        sizes = encoded.buffer_sizes  # waits for the kernel
        copier = self._local.copier
        if copier is None:
            encoded = encoded.cpu()
            return [np.asarray(encoded[i]).view(np.uint8) for i in range(count)]
        host = copier.copy(target, slot * (count - 1) + sizes[-1])
        return [host[k * slot : k * slot + n] for k, n in enumerate(sizes)]


@dataclass(frozen=True)
class _Sized:
    """A device buffer and its length in bytes (nvCOMP's arrays have no ``len``)."""

    array: Any
    nbytes: int

    def __len__(self) -> int:
        return self.nbytes


def import_nvcomp() -> Any:
    """``nvidia.nvcomp``, or :class:`MissingDependency` saying how to install it."""
    try:
        from nvidia import nvcomp
    except ImportError:
        raise MissingDependency(
            f"GPU compression (storage.compress_on) needs nvCOMP's Python package: pip install "
            f"'virtus-fpp[gpu]' (or {NVCOMP_REQUIREMENT})"
        ) from None
    return nvcomp


def _staging_torch() -> tuple[Any, str | None]:
    """``(torch, "cuda")`` when torch is a CUDA build with a device here, else
    ``(None, None)`` (torch is never required)."""
    try:
        import torch

        if torch.cuda.is_available():
            return torch, "cuda"
    except Exception:  # not installed, or a build whose libraries do not load here
        pass
    return None, None


@dataclass(frozen=True)
class CompressionPlan:
    """Who encodes a run's chunks (:func:`plan_compression`).

    Attributes
    ----------
    on : ``"gpu"`` or ``"cpu"``.
    encoder : ``"nvcomp 6.0.0.12"`` or ``"numcodecs 0.16.6"``.
    note : why ``auto`` chose the CPU (None otherwise).
    """

    on: str
    encoder: str
    note: str | None = None


def plan_compression(codec: str, compress_on: str, probe: Any = None) -> CompressionPlan:
    """Decide who encodes: ``cpu``; ``gpu`` (refused, in one line, without nvCOMP, without a
    CUDA device or for a codec the GPU does not write); ``auto`` the GPU when it works and
    ``codec`` is in :data:`GPU_CODECS`, else the CPU with a note saying why.

    ``probe`` makes the GPU compressor (default :class:`NvcompZstdFrames`; the tests pass a
    fake). Each worker process makes its own from the plan (:mod:`virtus.data.store`).

    Raises
    ------
    InputError : ``compress_on`` unknown, or ``gpu`` with a codec the GPU does not write.
    MissingDependency, BackendUnavailable : ``gpu`` without nvCOMP, or without a device.
    """
    if compress_on not in COMPRESS_ON:
        raise InputError("storage.compress_on", f"one of {', '.join(COMPRESS_ON)}", compress_on)
    cpu = cpu_encoder_name()
    if compress_on == "cpu":
        return CompressionPlan("cpu", cpu)
    if codec not in GPU_CODECS:
        if compress_on == "gpu":
            raise InputError(
                "storage.compress_on gpu", f"storage.codec {' or '.join(GPU_CODECS)}", codec
            )
        return CompressionPlan("cpu", cpu, f"codec {codec} is encoded on the CPU (the GPU "
                               f"writes {' and '.join(GPU_CODECS)})")  # fmt: skip
    try:
        gpu = (probe or _gpu_factory())()
    except (MissingDependency, BackendUnavailable) as error:
        if compress_on == "gpu":
            raise
        return CompressionPlan("cpu", cpu, f"compressing on the CPU: {error}")
    return CompressionPlan("gpu", gpu.name)


def encoding_description(
    codec: str, level: int, compress_on: str, encoders: Sequence[str]
) -> dict[str, Any]:
    """``dataset.json``'s ``encoding``: the stored bytes' format (codec, level, shuffle,
    zstd frames a chunk), the ``compress_on`` of the latest run and every encoder that wrote
    to the store (each shard record names its own)."""
    shuffle = None
    if codec == "shuffle-zstd":
        shuffle = "numcodecs.shuffle of multi-byte arrays"
    elif codec.startswith("blosc"):
        shuffle = "blosc byte shuffle"
    frames = None
    if codec in GPU_CODECS:
        frames = (
            "one or more standard zstd frames a chunk (RFC 8878): numcodecs >= "
            f"{READER_NUMCODECS} reads several"
        )
    return {
        "codec": codec,
        "level": level,
        "shuffle": shuffle,
        "zstd_frames": frames,
        "compress_on": compress_on,
        "encoders": sorted(set(encoders)),
    }


def _gpu_factory() -> Any:
    """What makes the GPU compressor: :class:`NvcompZstdFrames`, or its CPU twin named
    ``fake-nvcomp`` under :data:`FAKE_NVCOMP_ENV`."""
    if os.environ.get(FAKE_NVCOMP_ENV) == "1":

        def fake() -> CpuZstdFrames:
            twin = CpuZstdFrames()
            twin.name = f"fake-nvcomp ({twin.name})"
            twin.torch_device = "cpu" if _torch_importable() else None
            return twin

        return fake
    return NvcompZstdFrames


def _torch_importable() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def make_gpu_compressor(compress_on: str, codec: str) -> Any:
    """The batch compressor this process uses for a store (None: numcodecs, chunk by chunk):
    None for ``cpu`` or a codec not in :data:`GPU_CODECS`; for ``gpu`` the GPU's (errors
    raise: :func:`plan_compression` checked it before the run); for ``auto`` the GPU's, or
    None where it cannot be made (each shard record names who encoded it)."""
    if compress_on == "cpu" or codec not in GPU_CODECS:
        return None
    try:
        return _gpu_factory()()
    except (MissingDependency, BackendUnavailable):
        if compress_on == "gpu":
            raise
        return None


def encode_samples(
    encoders: dict[str, Any], samples: Sequence[dict[str, np.ndarray]], compressor: Any,
    on_device: Sequence[dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:  # fmt: skip
    """Every stored chunk of ``samples`` (name -> array each): name -> bytes (None: only the
    fill value) per sample, for the arrays with a shard encoder
    (:class:`~virtus.data.shards.ShardEncoder`). The zstd ones in one batch of
    ``compressor`` (:meth:`NvcompZstdFrames.encode_chunks`; from ``on_device``, the same
    samples as tensors on its ``torch_device``, when given); the others, and all without a
    ``compressor``, by their own numcodecs codecs."""
    out: list[dict[str, Any]] = [{} for _ in samples]
    batch, places = [], []
    for k, sample in enumerate(samples):
        for name, encoder in encoders.items():
            if encoder is None:
                continue
            if compressor is None or encoder.codec_name != "zstd":
                out[k][name] = encoder.encode(sample[name])
                continue
            raw = encoder.raw(sample[name])
            out[k][name] = None
            if raw is not None:
                batch.append((raw, encoder.shuffle))
                places.append((k, name))
    if batch:
        device = None if on_device is None else [on_device[k][name] for k, name in places]
        chunks = compressor.encode_chunks([b[0] for b in batch], [b[1] for b in batch], device)
        for (k, name), data in zip(places, chunks, strict=True):
            out[k][name] = data
    return out


def merge_encoding(description: dict[str, Any], encoders: Sequence[str]) -> bool:
    """Add ``encoders`` to a ``dataset.json`` description's ``encoding`` (a store extended,
    resumed, or written by more than one encoder); whether it changed (False without an
    ``encoding``: a store written before it was recorded)."""
    encoding = description.get("encoding")
    if not isinstance(encoding, dict):
        return False
    new = sorted(set(recorded_encoders(description)) | set(encoders))
    if new == encoding.get("encoders"):
        return False
    description["encoding"] = {**encoding, "encoders": new}
    return True


def recorded_encoders(description: Any) -> list[str]:
    """The encoders a ``dataset.json`` description lists (none for a missing or malformed
    ``encoding``)."""
    encoding = description.get("encoding") if isinstance(description, dict) else None
    encoders = encoding.get("encoders") if isinstance(encoding, dict) else None
    return [e for e in encoders if isinstance(e, str)] if isinstance(encoders, list) else []


#: Per process: ((compress_on, codec), its batch compressor or None), made once.
_PROCESS_COMPRESSOR: dict[int, tuple[Any, Any]] = {}


def process_compressor(description: dict[str, Any]) -> Any:
    """This process's batch compressor for a store's ``dataset.json`` description (its
    ``encoding.compress_on``, ``cpu`` for a store without one; its codec), made once a
    process (:func:`make_gpu_compressor`; None: numcodecs, chunk by chunk)."""
    encoding = description.get("encoding")
    on = encoding.get("compress_on") if isinstance(encoding, dict) else None
    key = (on if on in COMPRESS_ON else "cpu", description["config"]["storage"]["codec"])
    fake = os.environ.get(FAKE_NVCOMP_ENV)  # the testing hook may change within a process
    made = _PROCESS_COMPRESSOR.get(os.getpid())
    if made is None or made[0] != (key, fake):
        _PROCESS_COMPRESSOR.clear()  # a forked child's entry is its parent's
        made = _PROCESS_COMPRESSOR[os.getpid()] = ((key, fake), make_gpu_compressor(*key))
    return made[1]
