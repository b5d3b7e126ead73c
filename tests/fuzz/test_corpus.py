"""The fuzz corpus replayed: every stored case, then deterministic mutations of each seed.

Each reader (``tests/fuzz/targets.py``) must accept an input or refuse it with one of its
allowed errors (virtus's own); anything else fails the test, which lists the failing
inputs (saved under ``/tmp/virtus-fuzz-failures``) and how to replay each. About 5,500
generated cases and the ~130 stored ones run in about 30 s on 2 idle cores;
``VIRTUS_FUZZ_LONG=1 VIRTUS_FUZZ_CASES=100000`` runs the long campaign (README, Fuzzing).
"""

from __future__ import annotations

import pytest

from tests.fuzz.cases import (
    Outcome,
    cases_for,
    file_name,
    load_seed,
    report,
    run_mutations,
    run_one,
    seed_paths,
    store_case,
)
from tests.fuzz.targets import TARGETS, usd_available

FILE_READERS = [name for name in TARGETS if name != "store"]


def _skip_without_usd(reader: str) -> None:
    if reader == "usd" and not usd_available():
        pytest.skip("usd-core is not installed (pip install -e '.[usd]')")


STORED = [(reader, path) for reader in FILE_READERS for path in seed_paths(reader)]


@pytest.mark.parametrize("reader", FILE_READERS)
def test_every_reader_has_seeds(reader):
    assert seed_paths(reader), f"tests/fuzz/corpus/{reader} holds no seed"


@pytest.mark.parametrize(("reader", "path"), STORED, ids=[f"{r}/{p.name}" for r, p in STORED])
def test_stored_case(reader, path, tmp_path):
    _skip_without_usd(reader)
    target = TARGETS[reader]
    outcome = Outcome()
    run_one(target, load_seed(target, path), file_name(target, path.name), tmp_path / "case",
            path.name, outcome)  # fmt: skip
    assert not outcome.failures, report(outcome)


SEEDS = [(reader, path) for reader in FILE_READERS for path in seed_paths(reader)]


@pytest.mark.parametrize(("reader", "path"), SEEDS, ids=[f"{r}/{p.name}" for r, p in SEEDS])
def test_mutations(reader, path, tmp_path):
    _skip_without_usd(reader)
    target = TARGETS[reader]
    count = cases_for(reader, len(seed_paths(reader)))
    outcome = run_mutations(target, path.name, load_seed(target, path), count, tmp_path)
    assert outcome.run == count
    assert not outcome.failures, report(outcome)


OVERLAYS = [path.name for path in seed_paths("store")]


@pytest.mark.parametrize("name", OVERLAYS)
def test_store_stored_case(name, fuzz_stores, tmp_path):
    outcome = Outcome()
    data = store_case(fuzz_stores, name)
    run_one(TARGETS["store"], data, "input", tmp_path / "case", name, outcome)
    assert not outcome.failures, report(outcome)


@pytest.mark.parametrize("storage", ["zarr", "png"])
def test_store_mutations(storage, fuzz_stores, tmp_path):
    target = TARGETS["store"]
    seed = store_case(fuzz_stores, f"store-{storage}")
    count = cases_for("store", 2)
    outcome = run_mutations(target, f"store-{storage}", seed, count, tmp_path)
    assert outcome.run == count
    assert not outcome.failures, report(outcome)
