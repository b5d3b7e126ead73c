"""Synthetic datasets (virtus.data): configuration checks, exact labels that re-triangulate,
splits by object, a store that is byte-identical however it was made (one process, worker
processes, Ray, killed and resumed), verification, loaders and exports.

Everything runs on a tiny rig (64 x 48 camera, the paper's projector at a quarter of its
resolution, 1 spp, a 4-step Gray-coded sequence of 22 frames): ~40 ms a sample on 2 cores.
"""

from __future__ import annotations

import hashlib
import io
import json
import signal
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from virtus.cli import main
from virtus.data import DatasetConfig, DatasetStore, FringeDataset, generate, load_config
from virtus.data.export import export_webdataset
from virtus.data.labels import DIRECTIONS, MASKS
from virtus.data.sampling import Randomiser
from virtus.data.store import MANIFEST_DIR
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.patterns.phase import wrapped_phase
from virtus.reconstruct import points_from_decoded

#: Labels -> projector coordinates -> triangulation vs the stored points (the issue's bound).
#: Stored float32 phases (~90 rad: ulp 8e-6 rad = 2e-5 px) and points (ulp 6e-8 m at 1 m)
#: move a point by ~3e-7 m on this low-resolution projector (14 mm of depth per px).
RETRIANGULATION_M = 1e-6
#: Exact labels vs decoding the frames: the ideal projector shows sharp (nearest) pixels,
#: so decoded phase is a staircase up to half a projector px off the pixel-centre truth,
#: 2 pi 0.5 / 16 = 0.196 rad (measured median 0.10 rad); a wrong convention (sign, half
#: period, fringe order) is off by >= pi/2 on most pixels.
DECODE_AGREEMENT_RAD = 0.3
DECODE_MEDIAN_RAD = 0.15

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "datasets"


def tiny_rig() -> Rig:
    rig = default_rig()
    camera = Intrinsics(152.4, 152.4, 31.5, 23.5, 64, 48)
    return Rig(Camera(camera), Projector(rig.projector.intrinsics.scaled(0.25)), rig.proj2cam)


def tiny_config(folder: Path, name: str = "config.yaml", **changes) -> Path:
    """Write a tiny training configuration ``folder/name``; ``changes`` update its keys."""
    folder.mkdir(parents=True, exist_ok=True)
    tiny_rig().save_json(folder / "rig.json")
    data = {
        "mode": "training",
        "seed": 11,
        "num_samples": 16,
        "rig": {"file": "rig.json"},
        "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]},
        "objects": {"sources": [{"type": "sphere", "radius_m": [0.04, 0.08], "instances": 12}]},
        "storage": {"shard_samples": 4},
    }
    data.update(changes)
    path = folder / name
    path.write_text(yaml.safe_dump(data))
    return path


def vertical_store(folder: Path, num_samples: int, splits: dict[str, float]) -> Path:
    """Generate ``folder/store``: a tiny store of spheres before one plane, vertical Gray +
    4-step fringes only (the learn and report tests' training store); returns its path."""
    config = tiny_config(
        folder, num_samples=num_samples, splits=splits,
        fringes={"codings": ["gray"], "steps": [4], "periods": [16], "directions": ["v"]},
        planes={"count": [1, 1]},
    )  # fmt: skip
    generate(load_config(config), folder / "store")
    return folder / "store"


def store_files(path: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file of a store (the lock file aside)."""
    return {
        p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file() and p.name != ".virtus.lock"
    }


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in args])
    out, err = capsys.readouterr()
    return exit_info.value.code, out, err


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> Path:
    """A store of 12 samples with every object source (sphere, box, free-form, mesh files)."""
    import trimesh

    folder = tmp_path_factory.mktemp("mixed")
    (folder / "meshes").mkdir()
    trimesh.creation.capsule(height=0.05, radius=0.02).export(folder / "meshes" / "capsule.stl")
    trimesh.creation.cone(radius=0.03, height=0.06).export(folder / "meshes" / "cone.ply")
    trimesh.creation.annulus(0.01, 0.03, 0.02).export(folder / "meshes" / "ring.obj")
    sources = [
        {"type": "sphere", "instances": 6},
        {"type": "box", "instances": 6},
        {"type": "freeform", "instances": 3, "subdivisions": 2},
        {"type": "mesh_folder", "path": "meshes"},
    ]
    config = tiny_config(
        folder, num_samples=12, objects={"count": [1, 3], "sources": sources},
        planes={"count": [1, 2]}, sensor=["ideal", "webcam"],
    )  # fmt: skip
    generate(load_config(config), folder / "store")
    return folder / "store"


# -- configuration --------------------------------------------------------------------------


def test_config_round_trips_and_examples_validate(tmp_path) -> None:
    config = load_config(tiny_config(tmp_path))
    assert DatasetConfig.from_dict(config.to_dict()) == config
    for path in sorted(EXAMPLES.glob("*.yaml")):
        example = load_config(path)
        Randomiser(example, tmp_path / "assets").sample(0)
    assert {p.stem for p in EXAMPLES.glob("*.yaml")} >= {
        "scan",
        "training",
        "calibration",
        "ablation",
    }


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"objects": {"sourcez": []}}, "unknown key 'sourcez' (did you mean 'sources'?)"),
        ({"num_samples": 10_000_001}, "num_samples: expected an integer in 1..1000000"),
        ({"storage": {"codec": "gzip"}}, "storage.codec"),
        ({"splits": {"train": 0.5, "test": 0.2}}, "fractions summing to 1"),
        ({"fringes": {"steps": [2]}}, "fringes.steps[0]"),
    ],
)
def test_bad_configs_are_refused_naming_the_key(tmp_path, change, message) -> None:
    with pytest.raises(InputError, match=None) as error:
        load_config(tiny_config(tmp_path, **change))
    assert message in str(error.value)


def test_cli_refuses_bad_input_in_one_line_before_any_work(tmp_path, capsys) -> None:
    good = tiny_config(tmp_path / "good")
    bad = tiny_config(tmp_path / "bad", colour="red")
    (tmp_path / "empty_meshes").mkdir()
    empty = tiny_config(
        tmp_path, objects={"sources": [{"type": "mesh_folder", "path": "empty_meshes"}]}
    )
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    cases = [
        (bad, tmp_path / "out1", "unknown key 'colour'"),
        (empty, tmp_path / "out2", "no mesh file in"),
        (good, blocker / "store", "Not a directory"),
        (good, Path("/proc/virtus_store"), "/proc/virtus_store"),
    ]
    for config, out, message in cases:
        code, _, err = run_cli(
            ["dataset", "generate", "--config", str(config), "--out", str(out)], capsys
        )
        assert code == 2, err
        assert err.count("\n") == 1 and err.startswith("virtus: error:") and message in err, err
        assert not (out / "manifest").exists()
    # an existing store made with another configuration: refused, untouched
    store = tmp_path / "store"
    generate(load_config(good), store, num=4)
    before = store_files(store)
    other = tiny_config(tmp_path / "other", seed=12)
    code, _, err = run_cli(
        ["dataset", "generate", "--config", str(other), "--out", str(store)], capsys
    )
    assert code == 2 and err.count("\n") == 1
    assert "another configuration (config.seed: 12 here, 11 in the existing run)" in err
    assert store_files(store) == before


# -- labels ---------------------------------------------------------------------------------


def test_labels_retriangulate_to_the_stored_points(mixed) -> None:
    dataset = FringeDataset(mixed)
    assert len(dataset) == 12
    worst, pixels = 0.0, 0
    for item in range(len(dataset)):
        sample = dataset[item]
        sequence, rig = dataset.sequence(item), dataset.rig(item)
        mask = sample["masks"][MASKS.index("valid")].numpy()
        assert sample["frames"].dtype.is_floating_point is False
        proj_uv = np.stack(
            [
                sample["phase"][c].numpy().astype(np.float64)
                * sequence.periods(d)[0]
                / (2 * np.pi)
                / sequence.axis_scale(d)
                for c, d in enumerate(DIRECTIONS)
            ],
            axis=-1,
        )
        points = points_from_decoded(rig, proj_uv, mask)
        stored = sample["points"].numpy().astype(np.float64)
        assert np.isfinite(points[mask]).all()
        worst = max(worst, float(np.abs(points[mask] - stored[mask]).max(initial=0.0)))
        pixels += int(mask.sum())
        # the proj_uv label triangulates the same way
        direct = points_from_decoded(rig, sample["proj_uv"].numpy().astype(np.float64), mask)
        assert np.abs(direct[mask] - stored[mask]).max(initial=0.0) < RETRIANGULATION_M
    assert pixels > 10_000
    assert worst < RETRIANGULATION_M, worst


def test_labels_agree_with_decoding_and_with_each_other(mixed) -> None:
    store = DatasetStore.open(mixed)
    samples = store.samples()
    for index in (0, 5):
        arrays = store.read_sample(index)
        meta = samples[index]
        from virtus.patterns import PatternSequence

        sequence = PatternSequence.from_dict(meta["sequence"])
        frames = arrays["frames"][: meta["n_frames"]]
        decoded = sequence.decode(frames, full_scale=(1 << meta["bit_depth"]) - 1)
        masks = dict(zip(MASKS, arrays["masks"], strict=True))
        valid = masks["valid"] & decoded.mask & ~masks["saturated"]
        for c, d in enumerate(DIRECTIONS):
            phase = arrays["phase"][c].astype(np.float64)
            wrapped = arrays["wrapped"][c].astype(np.float64)
            order = arrays["order"][c]
            assert np.allclose(phase[valid], (wrapped + 2 * np.pi * order)[valid], atol=1e-4)
            assert wrapped[valid].min() >= -np.pi and wrapped[valid].max() < np.pi
            ratio = np.arctan2(arrays["numerator"][c], arrays["denominator"][c])
            assert np.allclose(ratio[valid], wrapped[valid], atol=1e-4)
            error = np.abs(getattr(decoded, f"phase_{d}")[valid] - phase[valid])
            assert np.median(error) < DECODE_MEDIAN_RAD
            assert np.mean(error < DECODE_AGREEMENT_RAD) > 0.98
            assert (order[~masks["valid"]] == -1).all()
            assert np.isnan(phase[~masks["valid"]]).all()
            # the modulation label (computed in float32) is the least-squares B of the
            # direction's finest phase set, as the decoder computes it in float64
            steps = [
                i for i, f in enumerate(sequence.frames)
                if f.kind == "phase" and f.direction == d and f.period == sequence.periods(d)[0]
            ]  # fmt: skip
            steps.sort(key=lambda i: sequence.frames[i].step)
            expected = wrapped_phase(frames[steps])[2]
            assert np.allclose(arrays["modulation"][c], expected, rtol=1e-5, atol=1e-3)
        depth = arrays["depth"]
        assert np.allclose(depth, arrays["points"][..., 2], equal_nan=True)
        hit = masks["hit"]
        assert (arrays["object_id"][hit] > 0).mean() > 0.99 and (
            arrays["object_id"][~hit] == 0
        ).all()
        assert len(meta["objects"]) >= int(arrays["object_id"].max())


def test_splits_are_by_object(mixed) -> None:
    samples = DatasetStore.open(mixed).samples()
    split_of: dict[str, str] = {}
    for meta in samples.values():
        for obj in meta["objects"]:
            if obj["type"] != "plane":
                assert split_of.setdefault(obj["key"], meta["split"]) == meta["split"], obj["key"]
    assert len(set(split_of.values())) >= 2


# -- store: determinism, storage formats, workers -------------------------------------------


def test_same_store_from_worker_processes_and_sample_independent_of_num(tmp_path) -> None:
    config = load_config(tiny_config(tmp_path))
    generate(config, tmp_path / "one", num=12)
    generate(config, tmp_path / "two", num=6)  # a smaller run (a partial last shard) ...
    generate(config, tmp_path / "two", num=12, workers=2)  # ... extended by 2 processes
    one, two = store_files(tmp_path / "one"), store_files(tmp_path / "two")
    assert one == two
    report = DatasetStore.open(tmp_path / "two").verify()
    assert report.ok and report.checked == 12


@pytest.mark.parametrize("codec", ["blosc-zstd", "blosc-lz4", "zstd", "none"])
def test_shards_written_directly_are_the_bytes_zarr_writes(tmp_path, codec) -> None:
    """The store writes shard files itself (virtus.data.shards): Zarr must read them as its
    own, so they must be Zarr's bytes -- every dtype of a store, a chunk of only the fill
    value (Zarr omits it) and a partial last shard."""
    import zarr

    from virtus.data.shards import ShardEncoder
    from virtus.data.store import zarr_compressor

    rng = np.random.default_rng(5)
    group = zarr.open_group(tmp_path, mode="w")
    for dtype, fill in [("uint8", 0), ("uint16", 0), ("float32", np.nan), ("float64", np.nan),
                        ("int32", -1), ("bool", False)]:  # fmt: skip
        shape = (7, 3, 12, 10)
        data = (rng.random(shape) * 300).astype(dtype)
        data[1] = fill
        if data.dtype.kind == "f":
            data[0, 0, :2] = np.nan
        arrays = [
            group.create_array(
                f"{dtype}_{name}",
                shape=shape,
                chunks=(1, *shape[1:]),
                shards=(3, *shape[1:]),
                dtype=dtype,
                fill_value=fill,
                compressors=zarr_compressor(codec, 3, "frames"),
            )  # fmt: skip
            for name in ("zarr", "direct")
        ]
        arrays[0][:] = data
        encoder = ShardEncoder.for_array(arrays[1], tmp_path / f"{dtype}_direct")
        assert encoder is not None
        for shard in range(3):
            encoder.write(
                shard, [encoder.encode(chunk) for chunk in data[3 * shard : 3 * shard + 3]]
            )
            theirs = tmp_path / f"{dtype}_zarr" / encoder.key(shard)
            assert encoder.path(shard).read_bytes() == theirs.read_bytes(), (dtype, shard)
        assert np.array_equal(arrays[1][:], data, equal_nan=data.dtype.kind == "f")
    unsupported = group.create_array("c_order_chunks", shape=(4, 6), chunks=(2, 3), dtype="u1")
    assert ShardEncoder.for_array(unsupported, tmp_path / "c_order_chunks") is None


def test_a_failed_sample_leaves_its_shard_unrecorded_and_the_rerun_completes(
    tmp_path, monkeypatch
) -> None:
    """In the one-process pipeline, labels are made on other threads than the renderer: a
    sample that fails there must fail the run and keep its shard out of the manifest."""
    import importlib

    generation = importlib.import_module("virtus.data.shardtask")
    config = load_config(tiny_config(tmp_path))
    generate(config, tmp_path / "reference", num=12)
    calls = {"n": 0}
    real = generation.sample_arrays

    def failing(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 8:  # sample 7: the last of shard 1, whose write is then queued
            raise RuntimeError("labelling failed")
        return real(*args, **kwargs)

    monkeypatch.setattr(generation, "sample_arrays", failing)
    with pytest.raises(RuntimeError, match="labelling failed"):
        generate(config, tmp_path / "store", num=12)
    assert 1 not in DatasetStore.open(tmp_path / "store").records()
    monkeypatch.setattr(generation, "sample_arrays", real)
    generate(config, tmp_path / "store", num=12)
    assert store_files(tmp_path / "store") == store_files(tmp_path / "reference")


def test_worker_tasks_take_several_shards_then_one_as_the_queue_empties() -> None:
    from collections import deque

    from virtus.data.generate import _TASK_SHARDS, _next_task

    queue, tasks = deque(range(180)), []
    while queue:
        tasks.append(_next_task(queue, 8))
    assert [s for task in tasks for s in task] == list(range(180))  # all, in order
    assert max(map(len, tasks)) == len(tasks[0]) == _TASK_SHARDS
    assert [len(task) for task in tasks[-16:]] == [1] * 16  # one shard each at the end
    assert _next_task(deque([5]), 8) == [5]


def test_shards_written_while_the_next_renders_are_the_same_files(tmp_path, monkeypatch) -> None:
    """A task of several shards, each written on a second thread while the next renders
    (two sets of buffers), writes the files of one shard at a time; a failure is raised
    after the shards before it are written, and leaves its own shard unrecorded."""
    import importlib
    import shutil

    generation = importlib.import_module("virtus.data.shardtask")
    config = load_config(tiny_config(tmp_path, storage={"shard_samples": 2}))
    generate(config, tmp_path / "reference", num=12)
    digest = DatasetStore.open(tmp_path / "reference").digest

    def emptied() -> Path:  # the reference without its shards' files and records
        path = tmp_path / "store"
        shutil.rmtree(path, ignore_errors=True)
        shutil.copytree(tmp_path / "reference", path)
        for file in sorted(path.rglob("*")):
            if file.is_file() and ("c" in file.relative_to(path).parts[1:2] or
                                   file.parent.name == MANIFEST_DIR):  # fmt: skip
                file.unlink()
        assert not DatasetStore.open(path).records()
        return path

    shards = list(range(6))
    results = generation.render_shards(emptied(), shards, 12, digest, overlap=True)
    assert [r["shard"] for r in results] == shards
    assert store_files(tmp_path / "store") == store_files(tmp_path / "reference")
    fill = generation._fill_shard

    def failing(store, randomiser, shard, *args):
        if shard == 4:
            raise RuntimeError("rendering failed")
        return fill(store, randomiser, shard, *args)

    monkeypatch.setattr(generation, "_fill_shard", failing)
    with pytest.raises(RuntimeError, match="rendering failed"):
        generation.render_shards(emptied(), shards, 12, digest, overlap=True)
    assert sorted(DatasetStore.open(tmp_path / "store").records()) == [0, 1, 2, 3]


@pytest.mark.parametrize("gpus", [0, 2], ids=["cpu workers", "workers pinned to 2 gpus"])
def test_worker_processes_with_tasks_of_several_shards_make_the_same_store(
    tmp_path, monkeypatch, gpus
) -> None:
    """Tasks of 3 shards, then 1; written while the next renders on (fake) GPUs only."""
    from virtus.data.devices import FAKE_GPUS_ENV

    monkeypatch.setenv(FAKE_GPUS_ENV, str(gpus))
    config = load_config(tiny_config(tmp_path, storage={"shard_samples": 1}))
    generate(config, tmp_path / "one", num=12, workers=1)
    report = generate(config, tmp_path / "two", num=12, workers=2)
    assert store_files(tmp_path / "one") == store_files(tmp_path / "two")
    devices = set(report.shard_devices.values())  # which worker took which: their speed
    assert devices <= {"0", "1"} if gpus else devices == {None}


def test_png_storage_holds_the_same_samples(tmp_path, capsys) -> None:
    config = tiny_config(tmp_path, num_samples=4)
    zarr_store, png_store = tmp_path / "zarr", tmp_path / "png"
    generate(load_config(config), zarr_store)
    code, _, err = run_cli(
        [
            "dataset",
            "generate",
            "--config",
            str(config),
            "--out",
            str(png_store),
            "--format",
            "png",
        ],
        capsys,
    )
    assert code == 0, err
    assert (png_store / "samples" / "000003" / "frames" / "021.png").is_file()
    a, b = DatasetStore.open(zarr_store).samples(), DatasetStore.open(png_store).samples()
    assert [m["checksum"] for m in a.values()] == [m["checksum"] for m in b.values()]
    assert DatasetStore.open(png_store).verify().ok
    item = FringeDataset(png_store, tensors=False)[2]
    assert np.array_equal(
        item["depth"], DatasetStore.open(zarr_store).read_sample(2)["depth"], equal_nan=True
    )


def test_verify_finds_corruption_and_missing_samples(tmp_path, capsys) -> None:
    store = tmp_path / "store"
    generate(load_config(tiny_config(tmp_path)), store, num=8)
    code, out, _ = run_cli(["dataset", "verify", str(store)], capsys)
    assert code == 0 and "ok: 8 samples checked" in out
    code, out, _ = run_cli(["dataset", "info", str(store), "--json"], capsys)
    assert code == 0 and json.loads(out)["complete"] == 8
    shard = store / "depth" / "c" / "1" / "0" / "0"
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))
    (store / "manifest" / "shard_000000.json").unlink()
    code, out, _ = run_cli(["dataset", "verify", str(store), "--json"], capsys)
    report = json.loads(out)
    assert code == 1 and report["missing"] == [0, 1, 2, 3]
    assert {index for index, _ in report["bad"]} <= {4, 5, 6, 7} and report["bad"]


def test_checksums_name_the_bad_array_and_old_sha256_stores_still_verify(tmp_path) -> None:
    from virtus.data.labels import _sha256_checksum, checksum_mismatches, sample_checksum

    path = tmp_path / "store"
    generate(load_config(tiny_config(tmp_path)), path, num=4)
    store = DatasetStore.open(path)
    record_path = path / "manifest" / "shard_000000.json"
    record = json.loads(record_path.read_text())
    arrays = store.read_sample(1)
    checksum = record["samples"][1]["checksum"]
    assert checksum == sample_checksum(arrays, store.layout) and checksum.startswith("crc32c:")
    # A changed value is caught in its own array, and only there.
    changed = {name: value.copy() for name, value in arrays.items()}
    changed["order"][1, 5, 7] += 1
    assert checksum_mismatches(changed, store.layout, checksum) == ["order"]
    assert checksum_mismatches(arrays, store.layout, "md5:0123") == ["sample"]
    assert checksum_mismatches(arrays, store.layout, "crc32c:00000000") == ["sample"]

    parts = checksum.split(".")
    depth = [a.name for a in store.layout].index("depth")
    parts[depth] = parts[depth][:-1] + ("0" if parts[depth][-1] != "0" else "1")
    record["samples"][1]["checksum"] = ".".join(parts)
    record["samples"][2]["checksum"] = _sha256_checksum(store.read_sample(2), store.layout)
    record_path.write_text(json.dumps(record))
    report = DatasetStore.open(path).verify()
    assert report.checked == 4 and report.bad == [(1, "checksum mismatch (depth)")]


# -- loaders and exports --------------------------------------------------------------------


def test_loader_splits_dataloader_and_missing_torch(mixed, monkeypatch) -> None:
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (the data extra)")
    train = FringeDataset(mixed, split="train", arrays=["depth", "masks"])
    test = FringeDataset(mixed, split="test", arrays=["depth", "masks"])
    assert not set(train.indices) & set(test.indices) and train.indices
    loader = torch.utils.data.DataLoader(train, batch_size=2, num_workers=0)
    batch = next(iter(loader))
    assert batch["depth"].shape == (2, 48, 64) and batch["depth"].dtype == torch.float32
    depth = batch["depth"][batch["masks"][:, MASKS.index("valid")]]
    assert 0.5 < float(depth.min()) and float(depth.max()) < 2.0  # metres, not normalised
    with pytest.raises(InputError, match="split"):
        FringeDataset(mixed, split="nope")
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(VirtusError, match=r"needs PyTorch: pip install 'virtus-fpp\[data\]'"):
        FringeDataset(mixed)
    assert FringeDataset(mixed, tensors=False)[0]["depth"].dtype == np.float32


def test_webdataset_export(mixed, tmp_path, capsys) -> None:
    out = tmp_path / "wds"
    code, _, err = run_cli(
        ["dataset", "export", str(mixed), "--webdataset", str(out), "--samples-per-tar", "5"],
        capsys,
    )
    assert code == 0, err
    tars = sorted(out.glob("all-*.tar"))
    assert len(tars) == 3
    with tarfile.open(tars[0]) as tar:
        names = tar.getnames()
        assert "000000.depth.npy" in names and "000000.json" in names
        depth = np.load(io.BytesIO(tar.extractfile("000000.depth.npy").read()))
        meta = json.loads(tar.extractfile("000000.json").read())
    assert np.array_equal(depth, DatasetStore.open(mixed).read_sample(0)["depth"], equal_nan=True)
    assert meta["index"] == 0 and "rig" in meta
    again = export_webdataset(mixed, tmp_path / "wds2", samples_per_tar=5)
    assert [p.read_bytes() for p in again] == [p.read_bytes() for p in tars]  # reproducible
    wds = pytest.importorskip("webdataset", reason="webdataset is not installed (the data extra)")
    first = next(iter(wds.WebDataset([str(t) for t in tars], shardshuffle=False).decode()))
    assert first["__key__"] == "000000" and np.array_equal(
        first["depth.npy"], depth, equal_nan=True
    )


@pytest.mark.parametrize("mode", ["scan", "calibration", "ablation"])
def test_every_mode_generates(tmp_path, mode) -> None:
    extra = {
        "scan": {"turntable": {"views": 3}},
        "calibration": {"board": {"spec": "4x7"}, "objects": {"sources": []},
                        "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]}},
        "ablation": {"ablation": {"materials": ["matte", "metal"], "ambients": ["dark"]}},
    }[mode]  # fmt: skip
    config = load_config(tiny_config(tmp_path, mode=mode, num_samples=4, **extra))
    generate(config, tmp_path / "store")
    samples = DatasetStore.open(tmp_path / "store").samples()
    assert len(samples) == 4
    if mode == "scan":
        assert [m["info"]["view"] for m in samples.values()] == [0, 1, 2, 0]
        assert samples[0]["objects"][0]["key"] == samples[2]["objects"][0]["key"]
    if mode == "ablation":
        assert [m["info"]["material"] for m in samples.values()] == ["matte", "metal"] * 2
    if mode == "calibration":
        assert samples[0]["objects"][0]["type"] == "board" and "board2cam" in samples[0]["info"]


# -- kill -9 and resume; Ray ----------------------------------------------------------------


#: ``python -c`` program: the CLI (arguments after the kill count) killed by SIGKILL in its
#: k-th shard-file write, after the temporary file is filled and before it is renamed into
#: place, and so at a point set by the work done, not by the clock: a run is cut short the
#: same way on a fast machine as on a slow one (a timer let fast machines finish the store).
_KILLED_IN_WRITE = """
import os, signal, sys
import virtus.data.shards as shards
kill_at, calls, atomic_write = int(sys.argv[1]), [0], shards.atomic_write
def write(path, fill):
    calls[0] += 1
    if calls[0] < kill_at:
        return atomic_write(path, fill)
    def fill_then_die(tmp):
        fill(tmp)
        os.kill(os.getpid(), signal.SIGKILL)
    return atomic_write(path, fill_then_die)
shards.atomic_write = write
from virtus.cli import main
main(sys.argv[2:])
"""


@pytest.mark.slow
def test_killed_and_resumed_runs_end_byte_identical(tmp_path) -> None:
    config = tiny_config(tmp_path, num_samples=200, storage={"shard_samples": 8})
    reference = tmp_path / "reference"
    generate(load_config(config), reference)
    out = tmp_path / "killed"
    arguments = ["dataset", "generate", "--config", str(config), "--out", str(out)]
    rng = np.random.default_rng(2026)
    complete = []
    # 25 shards of 13 arrays are 325 shard-file writes; 10 runs killed within 25 writes each
    # leave the store unfinished whatever the machine's speed.
    for kill_at in rng.integers(1, 26, size=10):
        killed = subprocess.run(
            [sys.executable, "-c", _KILLED_IN_WRITE, str(kill_at), *arguments],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert killed.returncode == -signal.SIGKILL, (kill_at, killed.stderr)
        complete.append(
            len(DatasetStore.open(out).samples()) if (out / "dataset.json").exists() else 0
        )
    assert complete == sorted(complete) and 0 < complete[-1] < 200, complete
    final = subprocess.run(
        [sys.executable, "-m", "virtus", *arguments], capture_output=True, text=True, timeout=300
    )
    assert final.returncode == 0, final.stderr
    mine, theirs = store_files(out), store_files(reference)
    differing = sorted(k for k in mine.keys() | theirs.keys() if mine.get(k) != theirs.get(k))
    assert not differing, (differing[:10], complete)
    verify = subprocess.run(
        [sys.executable, "-m", "virtus", "dataset", "verify", str(out)],
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0 and "ok: 200 samples checked" in verify.stdout, verify.stdout


def test_ray_cluster_makes_the_same_store(tmp_path) -> None:
    ray = pytest.importorskip(
        "ray", reason="Ray is not installed (optional: pip install 'virtus-fpp[ray]')"
    )
    config = load_config(tiny_config(tmp_path, num_samples=8))
    generate(config, tmp_path / "local")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        generate(config, tmp_path / "ray", ray="auto")
    finally:
        ray.shutdown()
    assert store_files(tmp_path / "ray") == store_files(tmp_path / "local")


def test_a_record_of_another_dataset_does_not_count_as_complete(mixed, tmp_path) -> None:
    # A manifest record whose dataset digest is not this store's (copied from another
    # store) must not make its shard complete: refused outright, or at least not counted.
    import shutil

    from virtus.errors import RunConflict

    copy = tmp_path / "store"
    shutil.copytree(mixed, copy)
    store = DatasetStore.open(copy)
    assert store.missing_shards(12) == [] and len(store.samples()) == 12
    record = copy / "manifest" / "shard_000001.json"
    data = json.loads(record.read_text())
    assert data["dataset"] == store.digest
    data["dataset"] = hashlib.sha256(b"another dataset").hexdigest()
    record.write_text(json.dumps(data))
    store = DatasetStore.open(copy)
    try:
        missing = store.missing_shards(12)
    except RunConflict as error:
        assert "shard_000001.json" in str(error)
    else:
        assert 1 in missing
        start, stop = store.shard_bounds(1, 12)
        assert not set(range(start, stop)) & set(store.samples())


@pytest.mark.parametrize("spec", ["4x7", "checker:6x9,square_mm=10"])  # fits the tiny rig
def test_calibration_mode_boards_are_textured_as_the_calibration_job_textures_them(
    tmp_path, spec
) -> None:
    from virtus.calib.board import board_from_spec
    from virtus.calib.scene import board_texture

    extra = {"board": {"spec": spec}, "objects": {"sources": []},
             "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]}}  # fmt: skip
    config = load_config(tiny_config(tmp_path, mode="calibration", num_samples=1, **extra))
    objects, _ = Randomiser(config, tmp_path / "assets")._board(np.random.default_rng(0))
    ((record, plane),) = objects
    assert record.type == "board"
    np.testing.assert_array_equal(plane.texture, board_texture(board_from_spec(spec)))
