"""The C allocator's settings (:mod:`virtus.allocator`), checked in fresh processes: the
thresholds reach glibc in this process and the environment of the processes it starts, a
variable the user set wins, and an 8 MB array then comes from the heap, not a mapping."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from virtus.allocator import ENVIRONMENT

#: Runs in a fresh interpreter: keep_freed_memory() (unless "default" is asked), then an
#: 8 MB numpy array held while glibc's mallinfo2 says how many bytes are in mappings.
PROBE = """
import ctypes, json, os, subprocess, sys
import numpy as np
from virtus.allocator import keep_freed_memory
changed = {} if sys.argv[1] == "default" else keep_freed_memory()
class Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks",
                "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL(None)
mapped = None
if hasattr(libc, "mallinfo2"):
    libc.mallinfo2.restype = Mallinfo2
    before = libc.mallinfo2().hblkhd
    array = np.ones(1 << 20)  # 8 MB
    mapped = libc.mallinfo2().hblkhd - before
child = subprocess.run([sys.executable, "-c", "import os, json; print(json.dumps("
                        "{k: v for k, v in os.environ.items() if k.startswith('MALLOC_')}))"],
                       capture_output=True, text=True, check=True).stdout
print(json.dumps({"changed": changed, "mapped": mapped, "child": json.loads(child)}))
"""


def probe(mode: str, **env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run(
        [sys.executable, "-c", PROBE, mode], env={**clean, **env},
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(out.stdout)


glibc = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not os.confstr("CS_GNU_LIBC_VERSION"),
    reason="glibc only",
)


@glibc
def test_freed_memory_is_kept_here_and_in_the_processes_started() -> None:
    kept, default = probe("keep"), probe("default")
    assert kept["changed"] == ENVIRONMENT
    assert kept["child"] == {k: str(v) for k, v in ENVIRONMENT.items()}
    assert default["child"] == {}
    if kept["mapped"] is None:
        pytest.skip("this glibc has no mallinfo2")
    assert default["mapped"] >= 8 << 20  # glibc's default: a mapping of its own
    assert kept["mapped"] == 0  # from the heap


@glibc
def test_a_variable_the_user_set_wins() -> None:
    result = probe("keep", MALLOC_TRIM_THRESHOLD_="131072")
    assert result["changed"] == {"MALLOC_MMAP_THRESHOLD_": ENVIRONMENT["MALLOC_MMAP_THRESHOLD_"]}
    assert result["child"]["MALLOC_TRIM_THRESHOLD_"] == "131072"
