"""The public face: ``virtus`` lists the names a user needs, loads them lazily, and every
dotted ``virtus.…`` name the README shows imports."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import virtus
from virtus.errors import (
    BackendUnavailable,
    DegenerateData,
    InputError,
    MissingDependency,
    RunConflict,
    VirtusError,
)

README = Path(__file__).resolve().parents[1] / "README.md"
HEAVY = ("mitsuba", "drjit", "cv2", "torch")


def test_import_virtus_loads_no_heavy_package() -> None:
    code = f"import sys, virtus; print([m for m in {HEAVY!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.parametrize("name", virtus.__all__)
def test_every_public_name_resolves(name) -> None:
    assert getattr(virtus, name) is not None


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'Scaner'"):
        virtus.Scaner  # noqa: B018


def test_the_face_gives_the_defining_objects() -> None:
    from virtus.capture.capture import Capture
    from virtus.scanner import Scanner

    assert virtus.Scanner is Scanner and virtus.Capture is Capture


def _readme_names() -> list[str]:
    names = set(re.findall(r"(?<![\w/.-])virtus(?:\.[A-Za-z_]\w*)+", README.read_text()))
    return sorted(n.rstrip(".") for n in names)


@pytest.mark.parametrize("dotted", _readme_names())
def test_every_dotted_name_in_the_readme_imports(dotted) -> None:
    parts = dotted.split(".")
    for split in range(len(parts), 0, -1):  # the longest importable module, then attributes
        try:
            obj = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for attribute in parts[split:]:
            obj = getattr(obj, attribute)
        return
    pytest.fail(f"{dotted} does not import")


def test_error_kinds_are_virtus_errors_and_the_matching_builtins() -> None:
    for kind in (InputError, RunConflict, DegenerateData, MissingDependency, BackendUnavailable):
        assert issubclass(kind, VirtusError)
    assert issubclass(InputError, ValueError) and issubclass(DegenerateData, ValueError)
    assert issubclass(MissingDependency, ImportError)
    assert issubclass(BackendUnavailable, RuntimeError)


def test_degenerate_points_raise_degenerate_data() -> None:
    import numpy as np

    from virtus.metrology import fit_plane

    line = np.column_stack([np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)])
    with pytest.raises(DegenerateData, match="plane fit"):
        fit_plane(line, 1e-3)


def test_a_directory_in_use_is_a_run_conflict(tmp_path) -> None:
    from virtus.io.runs import directory_lock

    code = (
        "from virtus.io.runs import directory_lock\n"
        "try:\n"
        f"    with directory_lock({str(tmp_path)!r}): pass\n"
        "except Exception as error:\n"
        "    print(type(error).__name__, error)\n"
    )
    with directory_lock(tmp_path):
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.stdout.startswith("RunConflict ") and "in use" in result.stdout, result
