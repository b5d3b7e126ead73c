"""Fixtures of the fuzz replay: the tiny dataset stores (made once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fuzz.cases import LONG, TALLY, tiny_stores


@pytest.fixture(scope="session")
def fuzz_stores(tmp_path_factory) -> dict[str, Path]:
    """``{"zarr": store, "png": store}``: 2 samples each, read-only for the tests (every
    case works on a copy written from the files' bytes)."""
    return tiny_stores(tmp_path_factory.mktemp("fuzz-stores"))


def pytest_terminal_summary(terminalreporter) -> None:
    """One line: the fuzz cases this run replayed and generated, and the failures."""
    if sum(TALLY.values()):
        terminalreporter.write_line(
            f"fuzz{' (long run)' if LONG else ''}: {TALLY['stored']} stored, "
            f"{TALLY['generated']} generated, {TALLY['hypothesis']} Hypothesis cases; "
            f"{TALLY['failures']} raised outside the allow-list (Hypothesis failures: above)"
        )
