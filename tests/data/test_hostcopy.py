"""The GPU compressor's copies through the CUDA driver (:mod:`virtus.data.hostcopy`), with a
stand-in driver whose "device memory" is host memory: a copy moves the right bytes, the
kept buffer grows and is page-locked once a size, a refused copy raises."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from virtus.data import hostcopy


class _Driver:
    """The driver calls :mod:`virtus.data.hostcopy` makes, on host memory (``memmove``),
    counting what is page-locked; ``fail`` makes the copies return an error code."""

    def __init__(self, fail: int = 0) -> None:
        self.locked: dict[int, int] = {}
        self.fail = fail

    def cuMemHostRegister_v2(self, address, nbytes, flags) -> int:  # noqa: N802
        assert address not in self.locked
        self.locked[address] = nbytes
        return 0

    def cuMemHostUnregister(self, address) -> int:  # noqa: N802
        del self.locked[address]
        return 0

    def cuMemcpyDtoH_v2(self, host, device, nbytes) -> int:  # noqa: N802
        if not self.fail:
            ctypes.memmove(host, device, nbytes)
        return self.fail


class _Device:
    """A "device" array: host bytes behind ``__cuda_array_interface__``."""

    def __init__(self, data: np.ndarray) -> None:
        self.data = data
        self.__cuda_array_interface__ = {
            "shape": data.shape, "typestr": "|u1", "data": (data.ctypes.data, False),
            "version": 3,
        }  # fmt: skip


def test_copies_move_the_bytes_through_a_kept_locked_buffer() -> None:
    driver = _Driver()
    copier = hostcopy.HostCopier(driver)
    rng = np.random.default_rng(3)
    source = _Device(rng.integers(0, 256, 5000, dtype=np.uint8))
    first = copier.copy(source, 3000)
    assert np.array_equal(first, source.data[:3000])
    assert list(driver.locked.values()) == [3000]
    again = copier.copy(source, 2000)  # fits: the same buffer, not locked again
    assert np.shares_memory(first, again) and list(driver.locked.values()) == [3000]
    assert np.array_equal(again, source.data[:2000])
    grown = copier.copy(source, 5000)  # grows: the old pages unlocked, the new ones locked
    assert np.array_equal(grown, source.data) and list(driver.locked.values()) == [5000]
    del copier, first, again, grown
    assert driver.locked == {}  # every page unlocked when the copier goes


def test_a_refused_copy_raises_with_the_drivers_code() -> None:
    copier = hostcopy.HostCopier(_Driver(fail=700))
    with pytest.raises(RuntimeError, match="CUDA driver error 700 copying 8 bytes to the host"):
        copier.copy(_Device(np.zeros(8, np.uint8)), 8)


def test_no_copier_without_the_driver(monkeypatch) -> None:
    monkeypatch.setattr(hostcopy, "driver", lambda: None)
    assert hostcopy.host_copier() is None
