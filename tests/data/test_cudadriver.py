"""How dataset workers ask the CUDA driver to let their threads sleep while they wait for
the GPU (:mod:`virtus.data.cudadriver`), with a stand-in driver: the flag asked for, on the
first visible device, and False whenever the driver or a device is missing or refuses."""

from __future__ import annotations

import pytest

from virtus.data import cudadriver


class _Driver:
    """cuInit, cuDeviceGet and cuDevicePrimaryCtxSetFlags_v2, recording what was asked;
    ``refuse`` names the call that returns an error."""

    def __init__(self, refuse: str | None = None) -> None:
        self.refuse = refuse
        self.flags: list[tuple[int, int]] = []

    def _status(self, name: str) -> int:
        return 100 if name == self.refuse else 0

    def cuInit(self, flags) -> int:  # noqa: N802
        assert flags == 0
        return self._status("cuInit")

    def cuDeviceGet(self, device, ordinal) -> int:  # noqa: N802
        assert ordinal == 0  # the first visible device: the one the worker is pinned to
        device._obj.value = 7
        return self._status("cuDeviceGet")

    def cuDevicePrimaryCtxSetFlags_v2(self, device, flags) -> int:  # noqa: N802
        self.flags.append((device.value, flags))
        return self._status("cuDevicePrimaryCtxSetFlags_v2")


def test_blocking_waits_asked_of_the_first_device(monkeypatch) -> None:
    fake = _Driver()
    monkeypatch.setattr(cudadriver, "driver", lambda: fake)
    assert cudadriver.block_while_waiting() is True
    assert fake.flags == [(7, 0x4)]  # CU_CTX_SCHED_BLOCKING_SYNC


@pytest.mark.parametrize("refused", ["cuInit", "cuDeviceGet", "cuDevicePrimaryCtxSetFlags_v2"])
def test_no_blocking_waits_when_the_driver_refuses(monkeypatch, refused) -> None:
    fake = _Driver(refuse=refused)
    monkeypatch.setattr(cudadriver, "driver", lambda: fake)
    assert cudadriver.block_while_waiting() is False
    assert len(fake.flags) == (1 if refused == "cuDevicePrimaryCtxSetFlags_v2" else 0)


def test_no_driver_no_blocking_waits(monkeypatch) -> None:
    cudadriver.driver.cache_clear()
    monkeypatch.setattr(cudadriver, "DRIVER_LIBRARY", "libvirtus-no-such-driver.so.1")
    try:
        assert cudadriver.driver() is None
        assert cudadriver.block_while_waiting() is False
    finally:
        cudadriver.driver.cache_clear()
