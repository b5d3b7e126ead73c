"""Damaged and tampered dataset stores: every read path checks checksums, a store's
description and records must be its own, and a Ray address that answers nothing is given
up on. Each refusal is one line naming the culprit (exit 2 through the CLI), nothing is
written, and the intact store is still accepted.

Stores are tiny (4 samples of a 64 x 48 camera, 2 shards of 2 samples): about a second each.
"""

from __future__ import annotations

import json
import shutil
import socket
import tarfile
from pathlib import Path

import pytest

from tests.data.test_dataset import run_cli, store_files
from tests.data.test_dataset import tiny_config as shared_config
from virtus.data import DamagedSample, DatasetStore, FringeDataset, generate, load_config
from virtus.data.export import export_webdataset
from virtus.errors import InputError, RunConflict
from virtus.io.runs import config_digest


def tiny_config(folder: Path, name: str = "config.yaml", **changes) -> Path:
    """The dataset tests' tiny configuration, 4 samples in shards of 2."""
    return shared_config(
        folder, name, **{"num_samples": 4, "storage": {"shard_samples": 2}, **changes}
    )


def refused(args: list[str], capsys, *culprits: str) -> str:
    """Run the CLI, expect exit 2 and one error line naming every culprit; the line."""
    code, _, err = run_cli(args, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("virtus: error:"), err
    for culprit in culprits:
        assert culprit in err, (culprit, err)
    return err


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> tuple[Path, Path]:
    """(configuration, store) of 4 complete samples; tests work on copies of the store."""
    folder = tmp_path_factory.mktemp("pristine")
    config = tiny_config(folder)
    generate(load_config(config), folder / "store")
    return config, folder / "store"


@pytest.fixture
def store(pristine, tmp_path) -> Path:
    copy = tmp_path / "store"
    shutil.copytree(pristine[1], copy)
    return copy


def corrupt_first_chunk(shard_file: Path) -> None:
    """Flip bytes inside the first chunk of a shard file (its first sample)."""
    data = bytearray(shard_file.read_bytes())
    for offset in range(20, 60):
        data[offset] ^= 0xFF
    shard_file.write_bytes(bytes(data))


# -- damaged samples ------------------------------------------------------------------------


def test_export_of_a_corrupt_shard_names_the_sample_and_writes_nothing(store, tmp_path, capsys):
    corrupt_first_chunk(store / "depth" / "c" / "1" / "0" / "0")  # sample 2's depth
    out = tmp_path / "wds"
    refused(["dataset", "export", store, "--webdataset", out], capsys, "sample 2", "damaged")
    assert not out.exists()
    # an existing folder is left as it was
    out.mkdir()
    refused(["dataset", "export", store, "--webdataset", out], capsys, "sample 2")
    assert list(out.iterdir()) == []
    # skipped and counted on request
    code, stdout, err = run_cli(
        ["dataset", "export", store, "--webdataset", out, "--skip-damaged",
         "--samples-per-tar", "2"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    assert "2 tar files, 1 damaged samples skipped (2)" in stdout
    keys = []
    for tar_path in sorted(out.glob("all-*.tar")):
        with tarfile.open(tar_path) as tar:
            keys += sorted({name.split(".")[0] for name in tar.getnames()})
    assert keys == ["000000", "000001", "000003"]
    # the library: a callback instead of the option
    seen: list[tuple[int, str]] = []
    export_webdataset(store, tmp_path / "lib", on_damaged=lambda i, why: seen.append((i, why)))
    assert [i for i, _ in seen] == [2] and "depth" in seen[0][1]


def test_an_intact_store_still_exports_and_verifies(pristine, tmp_path, capsys):
    code, stdout, err = run_cli(
        ["dataset", "export", pristine[1], "--webdataset", tmp_path / "wds", "--skip-damaged"],
        capsys,
    )
    assert code == 0 and "1 tar files, 0 damaged samples skipped" in stdout, err
    code, stdout, _ = run_cli(["dataset", "verify", pristine[1]], capsys)
    assert code == 0 and "ok: 4 samples checked" in stdout


def test_loaders_and_read_sample_check_every_read(store):
    corrupt_first_chunk(store / "depth" / "c" / "1" / "0" / "0")  # undecodable: sample 2
    record_path = store / "manifest" / "shard_000000.json"
    record = json.loads(record_path.read_text())
    parts = record["samples"][1]["checksum"].split(".")
    parts[-1] = f"{int(parts[-1], 16) ^ 1:08x}"  # the last array's checksum: sample 1
    record["samples"][1]["checksum"] = ".".join(parts)
    record_path.write_text(json.dumps(record))
    last = DatasetStore.open(store).layout[-1].name

    dataset = FringeDataset(store, tensors=False)
    assert dataset[0]["depth"].shape == (48, 64) and dataset[3]["index"] == 3
    with pytest.raises(DamagedSample, match=rf"sample 1 is damaged: checksum mismatch \({last}\)"):
        dataset[1]
    with pytest.raises(DamagedSample, match="sample 2 is damaged: depth unreadable") as error:
        dataset[2]
    assert str(error.value).count("\n") == 0 and error.value.index == 2
    # CRC-32C per array: reading only intact arrays of sample 1 works
    assert FringeDataset(store, arrays=["depth"], tensors=False)[1]["index"] == 1
    reader = DatasetStore.open(store)
    assert reader.read_sample(2, ("frames",))["frames"].shape[1:] == (48, 64)
    with pytest.raises(DamagedSample, match="sample 2"):
        reader.read_sample(2, ("depth",))
    with pytest.raises(InputError, match="index: expected a complete sample"):
        reader.read_sample(7)
    # an unchecked read returns what is stored, whatever its record says
    assert {a.name for a in reader.layout} == set(reader.read_sample(1, verify=False))


# -- a description or records that are not the store's ---------------------------------------


def _edit_description(store: Path, edit) -> None:
    file = store / "dataset.json"
    description = json.loads(file.read_text())
    edit(description)
    file.write_text(json.dumps(description))


def _reseed(description: dict, digest: bool) -> None:
    description["config"]["seed"] = 12
    description["identity"]["config"]["seed"] = 12
    if digest:
        description["identity_digest"] = config_digest(description["identity"])


@pytest.mark.parametrize(
    ("edit", "seed", "culprits"),
    [
        (lambda d: d["config"].update(seed=12), 11, ["dataset.json", "config.seed"]),
        (lambda d: _reseed(d, digest=False), 11, ["dataset.json", "identity_digest"]),
        # edited consistently, for the configuration of the run: the records tell
        (lambda d: _reseed(d, digest=True), 12, ["manifest/shard_000000.json", "another store"]),
    ],
    ids=["config", "identity", "identity-and-digest"],
)
def test_an_edited_description_is_refused_before_any_work(
    pristine, store, tmp_path, capsys, edit, seed, culprits
):
    _edit_description(store, edit)
    before = store_files(store)
    config = tiny_config(pristine[0].parent, f"seed{seed}.yaml", seed=seed)
    for args in (
        ["dataset", "generate", "--config", config, "--out", store],
        ["dataset", "verify", store],
        ["dataset", "info", store],
        ["dataset", "export", store, "--webdataset", tmp_path / "wds"],
    ):
        refused(args, capsys, *culprits)
    assert store_files(store) == before and not (tmp_path / "wds").exists()
    with pytest.raises((RunConflict, InputError)):
        FringeDataset(store, tensors=False)


def test_the_intact_store_is_reported_complete(pristine, store, capsys):
    code, stdout, err = run_cli(
        ["dataset", "generate", "--config", pristine[0], "--out", store], capsys
    )
    assert code == 0 and "4/4 samples complete (0 rendered" in stdout, err


@pytest.fixture(scope="module")
def other_store(tmp_path_factory) -> Path:
    """A store of another configuration (seed 12), same shard size."""
    folder = tmp_path_factory.mktemp("other")
    generate(load_config(tiny_config(folder, seed=12)), folder / "store")
    return folder / "store"


def test_a_record_of_another_store_is_refused_naming_it(
    pristine, store, other_store, tmp_path, capsys
):
    theirs = DatasetStore.open(other_store).digest
    assert theirs != DatasetStore.open(store).digest
    shutil.copy(other_store / "manifest" / "shard_000001.json", store / "manifest")
    before = store_files(store)
    for args in (
        ["dataset", "generate", "--config", pristine[0], "--out", store],
        ["dataset", "verify", store],
        ["dataset", "export", store, "--webdataset", tmp_path / "wds"],
    ):
        refused(args, capsys, "shard_000001.json", "another store")
    assert store_files(store) == before and not (tmp_path / "wds").exists()


def test_a_record_under_another_shard_name_is_refused(store, capsys):
    manifest = store / "manifest"
    shutil.copy(manifest / "shard_000000.json", manifest / "shard_000001.json")
    refused(["dataset", "verify", store], capsys, "shard_000001.json", "not the shard its name")
    (manifest / "shard_000001.json").write_text("{not json")
    refused(["dataset", "verify", store], capsys, "shard_000001.json", "unreadable")


# -- Ray ------------------------------------------------------------------------------------


def _closed_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_ray_address_without_a_cluster_ends_with_one_line(pristine, tmp_path, capsys):
    pytest.importorskip("ray", reason="Ray is not installed (optional)")
    out = tmp_path / "store"
    address = f"127.0.0.1:{_closed_port()}"
    base = ["dataset", "generate", "--config", pristine[0], "--out", out]
    refused([*base, "--ray", address], capsys, "--ray: expected", address)
    refused([*base, "--ray", "not-an-address"], capsys, "not-an-address")
    refused([*base, "--ray", address, "--ray-timeout", "0"], capsys, "ray_timeout")
    assert not out.exists()
