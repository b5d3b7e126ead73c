"""Who compresses a store (virtus.data.chunkcodecs): the GPU path's bytes are standard zstd
that plain numcodecs and zarr read on a CPU, and a store holds the same arrays whoever
encoded it.

Without a GPU the GPU path runs through its CPU twin (``VIRTUS_FAKE_NVCOMP=1``: the same
shuffle, pieces, batches, records, with numcodecs frames); nvCOMP's own bytes are checked
against a fixture made on a GPU (``scripts/make_nvcomp_fixture.py``), skipped until it exists.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import zarr

from tests.data.test_dataset import run_cli, store_files, tiny_config
from virtus.data import DatasetConfig, DatasetStore, generate, load_config
from virtus.data import chunkcodecs as codecs
from virtus.data.labels import sample_checksum
from virtus.data.shards import ShardEncoder
from virtus.errors import InputError, MissingDependency

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = Path(__file__).resolve().parent / "fixtures" / "nvcomp_zstd"
DTYPES = ("uint8", "uint16", "int32", "float32", "float64", "bool")


def fringe_like(dtype: str, shape=(3, 20, 30), seed: int = 4) -> np.ndarray:
    """Smooth data with noise (compresses like a label, not like random bytes)."""
    rng = np.random.default_rng(seed)
    ramp = np.cumsum(rng.normal(0.1, 1.0, shape), axis=-1) * 20
    if dtype == "bool":
        return ramp > 0
    return ramp.astype(dtype) if np.dtype(dtype).kind == "f" else np.abs(ramp).astype(dtype)


def unshuffle(data: np.ndarray, elementsize: int) -> np.ndarray:
    """numcodecs' own inverse of the byte shuffle (the reader's path)."""
    from numcodecs import Shuffle

    if elementsize <= 1:
        return data
    return np.frombuffer(Shuffle(elementsize=elementsize).decode(data), np.uint8)


def _script():
    spec = importlib.util.spec_from_file_location(
        "make_nvcomp_fixture", ROOT / "scripts" / "make_nvcomp_fixture.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# -- the bytes --------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
def test_shuffle_is_numcodecs_shuffle(dtype) -> None:
    from numcodecs import Shuffle

    array = fringe_like(dtype)
    raw = array.reshape(-1).view(np.uint8)
    size = array.dtype.itemsize
    ours = codecs.shuffle_bytes(raw, size)
    assert np.array_equal(ours, np.frombuffer(Shuffle(elementsize=size).encode(raw), np.uint8))
    assert size == 1 or not np.array_equal(ours, raw)
    with pytest.raises(ValueError, match="whole elements"):
        codecs.shuffle_bytes(raw[:-1], 2) if size > 1 else codecs.shuffle_bytes(raw[:3], 2)


def test_pieces_cover_every_byte_once() -> None:
    assert codecs.piece_bounds(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert codecs.piece_bounds(8, 4) == [(0, 4), (4, 8)]
    assert codecs.piece_bounds(3, 4) == [(0, 3)]
    assert codecs.piece_bounds(0, 4) == [(0, 0)]
    with pytest.raises(ValueError):
        codecs.piece_bounds(10, 0)


def test_staging_aligns_chunks_and_carves_the_shuffled_pieces() -> None:
    """The staging buffer nvCOMP reads (its host path, and the CPU twin): chunks at 16-byte
    aligned starts (nvCOMP's Zstd needs 4), pieces at multiples of the piece size inside
    them, every piece the shuffled chunk's bytes; frames regrouped per chunk."""
    arrays = [fringe_like("uint8", (3, 5, 7)), fringe_like("float32"), fringe_like("uint16")]
    chunks = [a.reshape(-1).view(np.uint8) for a in arrays]
    sizes = [1, 4, 2]
    starts, pieces, end = codecs.staging_layout([c.size for c in chunks], 256)
    assert starts[0] == 0 and all(start % codecs.STAGING_ALIGN == 0 for start in starts)
    assert starts[1] >= chunks[0].size and end == starts[-1] + chunks[-1].size
    assert all(offset % codecs.STAGING_ALIGN == 0 for offset, _ in pieces)
    staging = np.full(end, 7, np.uint8)
    codecs.stage_on_host(chunks, sizes, starts, staging)
    carved = [staging[o : o + n] for o, n in pieces]
    expected = [
        codecs.shuffle_bytes(c, size)[a:b]
        for c, size in zip(chunks, sizes, strict=True)
        for a, b in codecs.piece_bounds(c.size, 256)
    ]
    assert len(carved) == len(expected) and all(map(np.array_equal, carved, expected))
    joined = codecs.regroup(carved, [c.size for c in chunks], 256)
    assert [bytes(j) for j in joined] == [
        codecs.shuffle_bytes(c, s).tobytes() for c, s in zip(chunks, sizes, strict=True)
    ]
    with pytest.raises(ValueError, match="frames for"):
        codecs.regroup(carved[:-1], [c.size for c in chunks], 256)
    with pytest.raises(ValueError, match="multiple of 16"):
        codecs.staging_layout([10], 1000)
    with pytest.raises(ValueError, match="multiple of 16"):  # checked before nvCOMP is needed
        codecs.NvcompZstdFrames(piece_bytes=1000)


@pytest.mark.parametrize("piece_bytes", [1008, 4096, 1 << 18])
def test_frames_of_pieces_decode_with_plain_numcodecs(piece_bytes) -> None:
    """The GPU layout (a chunk = the zstd frames of its pieces, one after the other) is read
    by numcodecs' Zstd as one stream: several frames per chunk, a short last piece, shuffled
    and unshuffled chunks in one batch."""
    from numcodecs import Zstd

    arrays = [fringe_like(d) for d in DTYPES] + [fringe_like("float32")]
    raws = [a.reshape(-1).view(np.uint8) for a in arrays]
    sizes = [a.dtype.itemsize for a in arrays[:-1]] + [1]  # the last one unshuffled
    stored = codecs.CpuZstdFrames(piece_bytes=piece_bytes).encode_chunks(raws, sizes)
    for raw, size, data in zip(raws, sizes, stored, strict=True):
        decoded = np.frombuffer(Zstd().decode(data), np.uint8)
        assert np.array_equal(unshuffle(decoded, size), raw)
        frames = len(codecs.piece_bounds(raw.size, piece_bytes))
        assert frames >= (raw.size // piece_bytes)
        if piece_bytes == 1008:
            assert frames > 1
    whole = Zstd(level=1).encode(raws[3])  # one frame of the same bytes, unshuffled
    assert Zstd().decode(whole) == raws[3].tobytes()


def _zstd_without_content_size():
    """libzstd's ``ZSTD_compress2`` with the frame content size left out (as an encoder may
    write it, e.g. a streaming one); None without the system library."""
    name = ctypes.util.find_library("zstd")
    if name is None:
        return None
    lib = ctypes.CDLL(name)
    lib.ZSTD_createCCtx.restype = ctypes.c_void_p
    lib.ZSTD_CCtx_setParameter.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int]
    lib.ZSTD_compress2.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                                   ctypes.c_char_p, ctypes.c_size_t]  # fmt: skip
    lib.ZSTD_compress2.restype = ctypes.c_size_t
    context = lib.ZSTD_createCCtx()
    assert lib.ZSTD_CCtx_setParameter(context, 200, 0) == 0  # ZSTD_c_contentSizeFlag = 0

    def compress(data: bytes) -> bytes:
        out = ctypes.create_string_buffer(len(data) + 1024)
        size = lib.ZSTD_compress2(context, out, len(out), data, len(data))
        return out.raw[:size]

    return compress


def test_frames_without_a_content_size_decode_too() -> None:
    """nvCOMP's frames may leave the content size out of their headers; numcodecs must still
    decode them, alone and concatenated (else a GPU store would be unreadable)."""
    from numcodecs import Zstd

    compress = _zstd_without_content_size()
    if compress is None:
        pytest.skip("no system libzstd to write frames without a content size")
    raw = fringe_like("float32").tobytes()
    first, second = compress(raw[:1000]), compress(raw[1000:])
    assert first[4] & 0xC0 == 0 and not first[4] & 0x20  # no Frame_Content_Size field
    assert Zstd().decode(first + second) == raw


class _FakeNvcomp:
    """Just the part of nvCOMP's Python API that :class:`NvcompZstdFrames` uses (as_array,
    .cuda(), as_arrays carved by offsets, Codec(Zstd, RAW) with its bound, configuration and
    encode into given slots, the frames' sizes, .cpu(), indexing), on the host with
    numcodecs' zstd: the flow around nvCOMP -- staging, carving, slots, frames, regrouping
    -- runs in CI; nvCOMP's own bytes are the fixture's test."""

    __version__ = "0.0-fake"

    class BitstreamKind:
        RAW = "RAW"

    class Array:
        def __init__(self, data, copy=True) -> None:  # device memory: a copy
            self.data = np.array(data, dtype=np.uint8, copy=True) if copy else data

        def cuda(self):
            return _FakeNvcomp.Array(self.data)

        def __array__(self, dtype=None, copy=None):
            return self.data

    class Batch:
        def __init__(self, arrays) -> None:
            self.arrays = arrays

        def __len__(self) -> int:
            return len(self.arrays)

        def __getitem__(self, index):
            return self.arrays[index]

        @property
        def buffer_sizes(self) -> list[int]:
            return [a.data.size for a in self.arrays]

        def cpu(self):
            return _FakeNvcomp.Batch([_FakeNvcomp.Array(a.data) for a in self.arrays])

    class Codec:
        def __init__(self, algorithm, bitstream_kind, uncomp_chunk_size) -> None:
            assert (algorithm, bitstream_kind) == ("Zstd", "RAW")
            self.largest = uncomp_chunk_size

        def get_max_comp_buffer_size(self, array) -> int:
            return array.data.size + 64  # more than zstd's bound for these sizes

        def compression_config(self, sizes):
            assert all(0 < n <= self.largest for n in sizes)
            return tuple(sizes)

        def encode(self, batch, out, compression_config):
            from numcodecs import Zstd

            assert compression_config == tuple(a.data.size for a in batch.arrays)
            frames = [Zstd(level=1).encode(a.data) for a in batch.arrays]
            written = []
            for frame, slot in zip(frames, out.arrays, strict=True):
                assert len(frame) <= slot.data.size
                slot.data[: len(frame)] = np.frombuffer(frame, np.uint8)
                written.append(_FakeNvcomp.Array(slot.data[: len(frame)], copy=False))
            return _FakeNvcomp.Batch(written)

    @staticmethod
    def as_array(source):
        return _FakeNvcomp.Array(source)

    @staticmethod
    def as_arrays(buffer, offsets, sizes):
        data = np.asarray(buffer)
        return _FakeNvcomp.Batch(
            [
                _FakeNvcomp.Array(data[o : o + n], copy=False)
                for o, n in zip(offsets, sizes, strict=True)
            ]
        )


class _FakeCopier:
    """:class:`virtus.data.hostcopy.HostCopier` for :class:`_FakeNvcomp`'s "device" arrays:
    copies into one kept buffer, overwritten by each copy."""

    def __init__(self) -> None:
        self.kept = np.empty(0, np.uint8)
        self.copies = 0

    def copy(self, source, nbytes: int) -> np.ndarray:
        if self.kept.size < nbytes:
            self.kept = np.empty(nbytes, np.uint8)
        self.kept[:nbytes] = np.asarray(source)[:nbytes]
        self.copies += 1
        return self.kept[:nbytes]


@pytest.fixture
def fake_nvcomp(monkeypatch):
    """``from nvidia import nvcomp`` gives :class:`_FakeNvcomp`; no CUDA driver copies."""
    import types

    monkeypatch.delenv(codecs.FAKE_NVCOMP_ENV, raising=False)
    monkeypatch.setitem(sys.modules, "nvidia", types.SimpleNamespace(nvcomp=_FakeNvcomp))
    monkeypatch.setitem(sys.modules, "nvidia.nvcomp", _FakeNvcomp)
    monkeypatch.setattr(codecs, "_staging_torch", lambda: (None, None))  # the host-shuffle path
    monkeypatch.setattr(codecs, "host_copier", lambda: None)  # nvCOMP's own copies
    monkeypatch.setattr(codecs, "_PROCESS_COMPRESSOR", {})  # none made before counts
    return _FakeNvcomp


def test_planning_gpu_compression_does_not_import_torch(fake_nvcomp, monkeypatch) -> None:
    """The compressor that :func:`plan_compression` makes only to see that nvCOMP works
    looks for torch (seconds to import on a GPU host) only when it first stages chunks."""
    looked = []
    monkeypatch.setattr(codecs, "_staging_torch", lambda: looked.append(1) or (None, None))
    assert codecs.plan_compression("zstd", "gpu").on == "gpu"
    gpu = codecs.NvcompZstdFrames(piece_bytes=1008)
    assert not looked
    chunk = fringe_like(np.uint16, seed=1).reshape(-1).view(np.uint8)
    gpu.encode_chunks([chunk], [2])
    assert gpu.torch_device is None and looked == [1]  # once per compressor


@pytest.mark.parametrize("driver_copies", [False, True])
def test_the_nvcomp_flow_gives_the_cpu_twins_bytes(fake_nvcomp, monkeypatch, driver_copies) -> None:
    """Through a stand-in for nvCOMP that compresses each piece as numcodecs does, the GPU
    compressor gives byte for byte the CPU twin's chunks: its staging, carving, slots and
    regrouping are the twin's -- whether its frames come back in one copy of the slots'
    buffer into a kept one or through nvCOMP's copies -- and several calls reuse (and may
    grow) the buffers, each call's chunks independent of the kept host buffer the next copy
    reuses."""
    copier = _FakeCopier()
    if driver_copies:
        monkeypatch.setattr(codecs, "host_copier", lambda: copier)
    gpu = codecs.NvcompZstdFrames(piece_bytes=1008)
    assert gpu.name == "nvcomp 0.0-fake"
    twin = codecs.CpuZstdFrames(piece_bytes=1008)
    kept = []
    for seed in (1, 2, 3):
        arrays = [fringe_like(d, seed=seed) for d in DTYPES]
        if seed == 3:
            arrays = arrays[:2]  # fewer pieces than the slots kept from before
        chunks = [a.reshape(-1).view(np.uint8) for a in arrays]
        sizes = [a.dtype.itemsize for a in arrays]
        ours, theirs = gpu.encode_chunks(chunks, sizes), twin.encode_chunks(chunks, sizes)
        assert [bytes(c) for c in ours] == [bytes(c) for c in theirs]
        kept.append((ours, [bytes(c) for c in theirs]))
    for ours, theirs in kept:  # later copies did not change earlier chunks
        assert [bytes(c) for c in ours] == theirs
    assert copier.copies == (3 if driver_copies else 0)
    assert gpu.encode_chunks([], []) == []


def test_the_nvcomp_flow_compresses_device_chunks_as_host_ones(fake_nvcomp, monkeypatch) -> None:
    """With torch staging the chunks (torch's CPU standing in for the GPU), chunks the
    device already holds (any dtype of the same bytes) give the host chunks' bytes, as the
    twin compresses them; a device chunk of another size, or device chunks without torch,
    are refused."""
    import torch

    monkeypatch.setattr(codecs, "_staging_torch", lambda: (torch, "cpu"))
    gpu = codecs.NvcompZstdFrames(piece_bytes=1008)
    assert gpu.torch_device == "cpu"
    twin = codecs.CpuZstdFrames(piece_bytes=1008)
    arrays = [fringe_like(d, seed=7) for d in DTYPES]
    chunks = [a.reshape(-1).view(np.uint8) for a in arrays]
    sizes = [a.dtype.itemsize for a in arrays]
    twins = {"uint16": np.int16}  # torch has no general uint16 (the device buffers' dtype)
    device = [torch.from_numpy(a.view(twins.get(a.dtype.name, a.dtype)).copy()) for a in arrays]
    expected = [bytes(c) for c in twin.encode_chunks(chunks, sizes)]
    assert [bytes(c) for c in gpu.encode_chunks(chunks, sizes)] == expected  # torch staging
    assert [bytes(c) for c in gpu.encode_chunks(chunks, sizes, device)] == expected
    twin.torch_device = "cpu"
    assert [bytes(c) for c in twin.encode_chunks(chunks, sizes, device)] == expected
    with pytest.raises(ValueError, match="device chunk of"):
        gpu.encode_chunks(chunks, sizes, [device[0][:-1], *device[1:]])
    monkeypatch.setattr(codecs, "_staging_torch", lambda: (None, None))
    with pytest.raises(ValueError, match="need torch"):
        codecs.NvcompZstdFrames(piece_bytes=1008).encode_chunks(chunks, sizes, device)


@pytest.mark.parametrize("driver_copies", [False, True])
def test_a_store_compressed_through_the_nvcomp_flow(
    tmp_path, fake_nvcomp, monkeypatch, driver_copies
) -> None:
    if driver_copies:  # one copier a thread, as host_copier makes them
        monkeypatch.setattr(codecs, "host_copier", _FakeCopier)
    path, report = _store(tmp_path, "gpu", codec="shuffle-zstd", compress_on="gpu")
    assert report.encoders == {"nvcomp 0.0-fake": 2}
    records = DatasetStore.open(path).records()
    assert {r["encoder"] for r in records.values()} == {"nvcomp 0.0-fake"}
    assert len(_plain_zarr_samples(path)) == 6


# -- shard files ------------------------------------------------------------------------------


@pytest.mark.parametrize("codec", ["shuffle-zstd", "zstd"])
def test_shuffle_zstd_shards_are_zarrs_bytes_and_gpu_layout_reads_back(tmp_path, codec) -> None:
    """``shuffle-zstd`` shard files written directly are the bytes Zarr writes; the GPU
    layout (frames of pieces, from the batch path) in the same files reads back with plain
    zarr as the same arrays."""
    group = zarr.open_group(tmp_path, mode="w")
    for dtype in DTYPES:
        data = np.stack([fringe_like(dtype, seed=s) for s in range(5)])
        data[1] = False if dtype == "bool" else 0  # a chunk of only the fill value
        with codecs.quiet_numcodecs():
            arrays = [
                group.create_array(
                    f"{dtype}_{name}",
                    shape=data.shape,
                    chunks=(1, *data.shape[1:]),
                    shards=(3, *data.shape[1:]),
                    dtype=dtype,
                    fill_value=0,
                    compressors=codecs.zarr_compressor(codec, 3, "x", np.dtype(dtype).itemsize),
                )  # fmt: skip
                for name in ("zarr", "direct", "pieces")
            ]
        arrays[0][:] = data
        direct = ShardEncoder.for_array(arrays[1], tmp_path / f"{dtype}_direct")
        pieces = ShardEncoder.for_array(arrays[2], tmp_path / f"{dtype}_pieces")
        assert direct.codec_name == "zstd"
        itemsize = np.dtype(dtype).itemsize
        assert direct.shuffle == (itemsize if codec == "shuffle-zstd" and itemsize > 1 else 0)
        twin = codecs.CpuZstdFrames(level=3, piece_bytes=704)
        for shard in range(2):
            block = data[3 * shard : 3 * shard + 3]
            direct.write(shard, [direct.encode(chunk) for chunk in block])
            theirs = tmp_path / f"{dtype}_zarr" / direct.key(shard)
            assert direct.path(shard).read_bytes() == theirs.read_bytes(), (dtype, shard)
            samples = [{"x": chunk} for chunk in block]
            chunks = codecs.encode_samples({"x": pieces}, samples, twin)
            pieces.write(shard, [c["x"] for c in chunks])
        for name in ("direct", "pieces"):
            with codecs.quiet_numcodecs():
                again = zarr.open_array(tmp_path / f"{dtype}_{name}", mode="r")[:]
            assert np.array_equal(again, data), (dtype, name)


# -- stores -----------------------------------------------------------------------------------


def _store(tmp_path: Path, name: str, **storage) -> tuple[Path, object]:
    storage = {"shard_samples": 4, **storage}
    config = load_config(tiny_config(tmp_path / name, num_samples=6, storage=storage))
    report = generate(config, tmp_path / name / "store")
    return tmp_path / name / "store", report


def _plain_zarr_samples(path: Path) -> list[dict[str, np.ndarray]]:
    """Every sample read with plain zarr (no virtus reader), checked against the checksum
    its record holds (computed from the generated arrays before compression)."""
    store = DatasetStore.open(path)
    with codecs.quiet_numcodecs():
        group = zarr.open_group(path, mode="r")
        out = []
        for index, meta in store.samples().items():
            arrays = {a.name: np.asarray(group[a.name][index]) for a in store.layout}
            assert sample_checksum(arrays, store.layout) == meta["checksum"], index
            out.append(arrays)
    return out


def test_zstd_store_on_the_cpu_reads_back_with_plain_zarr(tmp_path) -> None:
    path, report = _store(tmp_path, "cpu", codec="zstd", compress_on="cpu")
    assert report.encoders == {codecs.cpu_encoder_name(): 2} and report.compression_note is None
    samples = _plain_zarr_samples(path)
    assert len(samples) == 6
    encoding = json.loads((path / "dataset.json").read_text())["encoding"]
    assert encoding["codec"] == "zstd" and encoding["encoders"] == [codecs.cpu_encoder_name()]
    assert encoding["compress_on"] == "cpu" and "numcodecs >= 0.16.4" in encoding["zstd_frames"]
    records = DatasetStore.open(path).records()
    assert {r["encoder"] for r in records.values()} == {codecs.cpu_encoder_name()}


def test_gpu_path_writes_the_arrays_the_cpu_writes(tmp_path, monkeypatch) -> None:
    """The GPU path (its CPU twin, pieces small enough for several frames a chunk): a store
    with the same arrays and checksums as the CPU's, read by plain zarr; other bytes; the
    encoder named in the records and dataset.json; resumed on the CPU, both named."""
    monkeypatch.setattr(codecs, "PIECE_BYTES", 2000)
    cpu_path, _ = _store(tmp_path, "cpu", codec="shuffle-zstd", compress_on="cpu")
    monkeypatch.setenv(codecs.FAKE_NVCOMP_ENV, "1")
    gpu_path, report = _store(tmp_path, "gpu", codec="shuffle-zstd", compress_on="gpu")
    fake = next(iter(report.encoders))
    assert fake.startswith("fake-nvcomp") and report.encoders[fake] == 2
    cpu, gpu = _plain_zarr_samples(cpu_path), _plain_zarr_samples(gpu_path)
    for a, b in zip(cpu, gpu, strict=True):
        assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)
    cpu_files, gpu_files = store_files(cpu_path), store_files(gpu_path)
    assert cpu_files["phase/c/0/0/0/0"] != gpu_files["phase/c/0/0/0/0"]  # other frames
    assert DatasetStore.open(gpu_path).verify().ok
    # extended on the CPU (compress_on is not part of the identity): both encoders named
    monkeypatch.delenv(codecs.FAKE_NVCOMP_ENV)
    config = load_config(tiny_config(tmp_path / "gpu", num_samples=10, storage={
        "shard_samples": 4, "codec": "shuffle-zstd", "compress_on": "cpu"}))  # fmt: skip
    generate(config, gpu_path)
    store = DatasetStore.open(gpu_path)
    assert store.description["encoding"]["encoders"] == sorted([fake, codecs.cpu_encoder_name()])
    cpu_name = codecs.cpu_encoder_name()  # shard 1 was partial: rendered again, on the CPU
    assert [r["encoder"] for _, r in sorted(store.records().items())] == [fake, cpu_name, cpu_name]
    assert store.verify().ok and store.verify().checked == 10


def test_pipelined_and_worker_runs_batch_on_the_gpu_path(tmp_path, monkeypatch) -> None:
    """Spawned workers make their own GPU compressor (the hook travels in the environment)
    and give the store a one-process run gives."""
    monkeypatch.setenv(codecs.FAKE_NVCOMP_ENV, "1")
    one, _ = _store(tmp_path, "one", codec="zstd", compress_on="auto")
    config = load_config(tiny_config(tmp_path / "two", num_samples=6, storage={
        "shard_samples": 2, "codec": "zstd", "compress_on": "auto"}))  # fmt: skip
    report = generate(config, tmp_path / "two" / "store", workers=2)
    assert all(name.startswith("fake-nvcomp") for name in report.encoders)
    assert sum(report.encoders.values()) == 3
    for a, b in zip(
        _plain_zarr_samples(one), _plain_zarr_samples(tmp_path / "two" / "store"), strict=True
    ):
        assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)


# -- choosing who compresses ------------------------------------------------------------------


def _no_nvcomp(monkeypatch) -> None:
    monkeypatch.delenv(codecs.FAKE_NVCOMP_ENV, raising=False)
    monkeypatch.setitem(sys.modules, "nvidia.nvcomp", None)  # import fails as if absent
    monkeypatch.setattr(codecs, "_PROCESS_COMPRESSOR", {})  # none made before counts


def test_auto_falls_back_to_the_cpu_and_says_so(tmp_path, monkeypatch) -> None:
    _no_nvcomp(monkeypatch)
    with pytest.warns(UserWarning, match="compress_on auto: compressing on the CPU.*virtus-fpp"):
        path, report = _store(tmp_path, "auto", codec="zstd", compress_on="auto")
    assert "nvCOMP" in report.compression_note
    assert report.encoders == {codecs.cpu_encoder_name(): 2}
    plan = codecs.plan_compression("blosc-zstd", "auto")  # nothing to fall back from
    assert plan.on == "cpu" and "blosc-zstd" in plan.note


def test_gpu_without_nvcomp_is_refused_in_one_line_before_anything_is_written(
    tmp_path, monkeypatch, capsys
) -> None:
    _no_nvcomp(monkeypatch)
    with pytest.raises(MissingDependency, match=r"pip install 'virtus-fpp\[gpu\]'"):
        codecs.plan_compression("zstd", "gpu")
    config = tiny_config(tmp_path, storage={"codec": "shuffle-zstd", "compress_on": "gpu"})
    code, out, err = run_cli(
        ["dataset", "generate", "--config", config, "--out", tmp_path / "store"], capsys
    )
    assert code == 2 and "virtus-fpp[gpu]" in err and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err and not (tmp_path / "store").exists()


def test_gpu_without_a_device_is_refused(monkeypatch) -> None:
    from virtus.errors import BackendUnavailable

    def no_device() -> None:
        raise BackendUnavailable("storage.compress_on gpu: nvCOMP finds no usable CUDA device")

    with pytest.raises(BackendUnavailable, match="no usable CUDA device"):
        codecs.plan_compression("zstd", "gpu", probe=no_device)
    plan = codecs.plan_compression("zstd", "auto", probe=no_device)
    assert plan.on == "cpu" and "no usable CUDA device" in plan.note


@pytest.mark.parametrize(
    ("storage", "message"),
    [
        ({"compress_on": "tpu"}, "storage.compress_on: expected one of auto, cpu, gpu"),
        ({"compress_on": ["gpu"]}, "storage.compress_on: expected one of auto, cpu, gpu"),
        ({"compress_on": "gpu", "codec": "blosc-zstd"}, "storage.codec zstd or shuffle-zstd"),
        ({"codec": "gpu-zstd"}, "storage.codec: expected one of"),
    ],
)
def test_bad_compression_settings_are_refused(storage, message) -> None:
    with pytest.raises(InputError, match=message):
        DatasetConfig.from_dict({"mode": "training", "storage": storage})


def test_compress_on_round_trips_but_is_not_part_of_the_identity() -> None:
    gpu = DatasetConfig.from_dict(
        {"mode": "training", "storage": {"codec": "zstd", "compress_on": "gpu"}}
    )
    cpu = DatasetConfig.from_dict(
        {"mode": "training", "storage": {"codec": "zstd", "compress_on": "cpu"}}
    )
    assert DatasetConfig.from_dict(gpu.to_dict()) == gpu
    assert gpu.identity() == cpu.identity() and "compress_on" not in gpu.stored_dict()["storage"]
    # the default: measured, compressing on the GPU was the slower
    assert DatasetConfig.from_dict({"mode": "training"}).compress_on == "cpu"


# -- nvCOMP's own bytes -----------------------------------------------------------------------


def check_fixture(folder: Path) -> dict:
    """Every case of a fixture folder decodes with plain numcodecs to its array, and reads
    back through plain zarr from a shard file holding the bytes (shuffle-zstd metadata for
    shuffled cases, zstd for the others). Returns the fixture's meta.json."""
    from numcodecs import Zstd

    meta = json.loads((folder / "meta.json").read_text())
    assert meta["format"] == "virtus.nvcomp_fixture/1" and meta["cases"]
    group = zarr.open_group(folder.parent / f"{folder.name}-zarr", mode="w")
    for name, case in meta["cases"].items():
        array = np.load(folder / f"{name}.npy", allow_pickle=False)
        data = (folder / f"{name}.zst").read_bytes()
        raw = array.reshape(-1).view(np.uint8)
        decoded = np.frombuffer(Zstd().decode(data), np.uint8)
        assert np.array_equal(unshuffle(decoded, case["elementsize"]), raw), name
        codec = "shuffle-zstd" if case["elementsize"] > 1 else "zstd"
        with codecs.quiet_numcodecs():
            stored = group.create_array(
                name, shape=(1, *array.shape), chunks=(1, *array.shape),
                shards=(1, *array.shape), dtype=array.dtype, fill_value=0,
                compressors=codecs.zarr_compressor(codec, 1, name, array.dtype.itemsize),
            )  # fmt: skip
            encoder = ShardEncoder.for_array(stored, Path(group.store.root) / name)
            encoder.write(0, [data])
            assert np.array_equal(
                zarr.open_array(Path(group.store.root) / name, mode="r")[0], array
            )
    return meta


def test_the_fixture_script_and_its_check_on_the_cpu_twin(tmp_path) -> None:
    script = _script()
    assert script.write_fixture(
        tmp_path / "twin", codecs.CpuZstdFrames(piece_bytes=script.PIECE_BYTES)
    )
    meta = check_fixture(tmp_path / "twin")
    assert meta["cases"]["frames"]["raw_bytes"] > 2 * script.PIECE_BYTES  # several frames


@pytest.mark.skipif(
    not (FIXTURE / "meta.json").is_file(),
    reason="no nvCOMP fixture yet: make it on a GPU with scripts/make_nvcomp_fixture.py",
)
def test_nvcomp_bytes_read_back_with_plain_numcodecs_and_zarr(tmp_path) -> None:
    import shutil

    shutil.copytree(FIXTURE, tmp_path / "nvcomp_zstd")
    meta = check_fixture(tmp_path / "nvcomp_zstd")
    assert meta["encoder"].startswith("nvcomp ")
