"""The cases of the replay: stored seeds, deterministic mutations of them, the budget.

* Stored cases: every entry of ``corpus/<reader>/`` (a file, or a folder for the folder
  readers), valid examples, hand-made malformed inputs and the regressions the fuzzer found
  (``regress-*``), read as they are.
* Generated cases: :func:`tests.fuzz.mutate.mutation` of each seed, ``cases_per_seed`` of
  them. The budget (:data:`CI_CASES`) spreads about 5,600 cases over the readers by their
  cost; ``VIRTUS_FUZZ_LONG=1`` multiplies it up to ``VIRTUS_FUZZ_CASES`` (default 100,000).
* The dataset store has no stored seed: a tiny Zarr store and a tiny PNG store are generated
  once per session (:func:`tiny_stores`, about a second each); its stored cases are overlays
  (``corpus/store/zarr-*``, ``png-*``: files that replace the tiny store's, and a
  ``REMOVED`` list of files taken away), see :func:`store_case`.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import threading
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.fuzz.mutate import mutation
from tests.fuzz.targets import CORPUS, Data, FuzzFailure, Target, read_folder, run_case

#: Generated cases per reader in CI (before the per-seed rounding up), by the reader's cost.
CI_CASES = {
    "sequence": 520, "calibration": 520, "calibration_txt": 300, "pose_npz": 300, "scene": 400,
    "dataset_config": 300, "usd": 240, "sensor": 300, "projector": 300, "capture": 320,
    "ply": 400, "mesh": 400, "npy": 400, "image": 400, "texture": 300, "store": 80,
}  # fmt: skip
#: The long run: ``VIRTUS_FUZZ_LONG=1``; ``VIRTUS_FUZZ_CASES`` cases in all (generated).
LONG = os.environ.get("VIRTUS_FUZZ_LONG", "") not in ("", "0")
LONG_CASES = int(os.environ.get("VIRTUS_FUZZ_CASES", "100000"))
#: A case running longer than this is a failure (a reader that hangs on a small input).
CASE_DEADLINE_S = float(os.environ.get("VIRTUS_FUZZ_DEADLINE_S", "20"))
#: Where failing inputs are written (named in the failure message).
FAILURES = Path(os.environ.get("VIRTUS_FUZZ_FAILURES", "/tmp/virtus-fuzz-failures"))


def cases_for(reader: str, seeds: int) -> int:
    """Generated cases of each of a reader's ``seeds`` seeds."""
    total = CI_CASES[reader]
    if LONG:
        total = total * LONG_CASES / sum(CI_CASES.values())
    return max(1, math.ceil(total / max(1, seeds)))


def seed_paths(reader: str) -> list[Path]:
    """The stored entries of ``corpus/<reader>`` (sorted; hidden files left out)."""
    folder = CORPUS / reader
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if not p.name.startswith("."))


def load_seed(target: Target, path: Path) -> Data:
    return read_folder(path) if target.folder else path.read_bytes()


def file_name(target: Target, seed_name: str) -> str:
    """The name a case is written under: the seed's (its suffix picks the format)."""
    return "input" if target.folder else "input" + (Path(seed_name).suffix or ".bin")


# -- running --------------------------------------------------------------------------------


class CaseTimeout(FuzzFailure):
    """A case ran past :data:`CASE_DEADLINE_S`."""


@contextlib.contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Raise :class:`CaseTimeout` in the main thread after ``seconds`` (POSIX only)."""
    if (
        seconds <= 0
        or not hasattr(signal, "setitimer")
        or threading.current_thread() is not threading.main_thread()
    ):
        yield
        return

    def expire(signum: int, frame: Any) -> None:
        raise CaseTimeout(f"case ran past {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


#: Cases run in this process, by kind (``stored``, ``generated``, ``hypothesis``), and the
#: failures among them: the session's summary line (``conftest.py``).
TALLY = {"stored": 0, "generated": 0, "hypothesis": 0, "failures": 0}


@dataclass
class Outcome:
    """What a batch of cases did."""

    run: int = 0
    accepted: int = 0
    refused: int = 0
    seconds: float = 0.0
    failures: list[str] = field(default_factory=list)


def _save(reader: str, label: str, data: Data, name: str) -> Path:
    folder = FAILURES / reader
    folder.mkdir(parents=True, exist_ok=True)
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in label)
    target = folder / (safe + (Path(name).suffix if isinstance(data, bytes) else ""))
    if target.is_dir():
        shutil.rmtree(target)
    if isinstance(data, bytes):
        target.write_bytes(data)
    else:
        for relative, content in data.items():
            file = target / relative
            file.parent.mkdir(parents=True, exist_ok=True)
            file.mkdir(exist_ok=True) if content is None else file.write_bytes(content)
    return target


def _describe(data: Data) -> str:
    if isinstance(data, bytes):
        head = data[:160]
        return f"{len(data)} bytes: {head!r}{'...' if len(data) > 160 else ''}"
    return f"folder of {len(data)} files"


def run_one(
    target: Target,
    data: Data,
    name: str,
    workdir: Path,
    label: str,
    outcome: Outcome,
    kind: str = "stored",
) -> None:
    """Run one case into ``outcome``; a failure is recorded (input saved), not raised."""
    TALLY[kind] += 1
    start = time.perf_counter()
    try:
        with deadline(CASE_DEADLINE_S):
            result = run_case(target, data, name, workdir)
    except Exception as error:  # noqa: BLE001 (every escape is the finding)
        saved = _save(target.name, label, data, name)
        last = traceback.format_exception(error)
        frames = "".join(last[-4:]).rstrip()
        TALLY["failures"] += 1
        outcome.failures.append(
            f"{label}: {type(error).__name__}: {str(error)[:300]}\n"
            f"  input: {_describe(data)}\n  saved: {saved}\n  replay: python -m "
            f"tests.fuzz.replay {target.name} {label}\n{frames}"
        )
    else:
        outcome.accepted += result == "accepted"
        outcome.refused += result == "refused"
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    outcome.run += 1
    outcome.seconds += time.perf_counter() - start


def run_mutations(
    target: Target, seed_name: str, seed: Data, count: int, workdir: Path, start: int = 0
) -> Outcome:
    """Cases ``start .. start + count - 1`` of one seed."""
    outcome = Outcome()
    name = file_name(target, seed_name)
    suffix = Path(seed_name).suffix.lower()
    for index in range(start, start + count):
        data, what = mutation(target.name, seed_name, seed, index, suffix)
        label = f"{seed_name} {index}"
        before = len(outcome.failures)
        run_one(target, data, name, workdir / f"case{index}", label, outcome, "generated")
        if len(outcome.failures) > before:
            outcome.failures[-1] = outcome.failures[-1].replace("\n", f"\n  mutation: {what}\n", 1)
    return outcome


def report(outcome: Outcome, limit: int = 8) -> str:
    shown = "\n\n".join(outcome.failures[:limit])
    more = len(outcome.failures) - limit
    return (
        f"{len(outcome.failures)} of {outcome.run} cases raised outside the allow-list"
        + (f" ({more} more not shown)" if more > 0 else "")
        + ":\n\n"
        + shown
    )


# -- the tiny stores ------------------------------------------------------------------------


def store_case(stores: dict[str, Path], name: str) -> dict[str, bytes]:
    """The files of a store case: ``store-zarr``/``store-png`` (a tiny store as made), or
    an overlay of ``corpus/store`` (``zarr-*``/``png-*``) applied to the tiny store it names."""
    if name.startswith("store-"):
        return read_folder(stores[name.removeprefix("store-")])
    overlay = CORPUS / "store" / name
    files = read_folder(stores[name.split("-", 1)[0]])
    for relative, content in read_folder(overlay).items():
        if relative == "REMOVED":
            for gone in content.decode().split():
                files.pop(gone, None)
        else:
            files[relative] = content
    return files


def tiny_stores(folder: Path) -> dict[str, Path]:
    """A tiny Zarr store and a tiny PNG store (2 samples of a 64 x 48 camera, a shard
    each) made under ``folder``; ``{"zarr": path, "png": path}``."""
    import yaml

    from virtus.data import generate, load_config
    from virtus.geometry.devices import Camera, Projector, Rig, default_rig
    from virtus.geometry.optics import Intrinsics

    folder.mkdir(parents=True, exist_ok=True)
    rig = default_rig()
    camera = Intrinsics(152.4, 152.4, 31.5, 23.5, 64, 48)
    Rig(Camera(camera), Projector(rig.projector.intrinsics.scaled(0.25)), rig.proj2cam).save_json(
        folder / "rig.json"
    )
    config = {
        "mode": "training",
        "seed": 11,
        "num_samples": 2,
        "rig": {"file": "rig.json"},
        "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]},
        "objects": {"sources": [{"type": "sphere", "radius_m": [0.04, 0.08], "instances": 4}]},
        "storage": {"shard_samples": 1},
    }
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    stores = {}
    for storage in ("zarr", "png"):
        path = folder / f"store-{storage}"
        if not (path / "dataset.json").is_file():
            generate(load_config(folder / "config.yaml"), path, storage=storage)
        (path / ".virtus.lock").unlink(missing_ok=True)
        stores[storage] = path
    return stores
