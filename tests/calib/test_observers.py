"""Where poses are observed (:mod:`virtus.calib.observers`): the choice made from a
calibration's ``processes`` argument, and threads observing poses side by side giving the
observations of one after the other (exact synthetic board views, no renderer)."""

from __future__ import annotations

import contextlib
import sys

import numpy as np
import pytest

from tests.pipeline.test_calibrate_resume import quarter_rig
from virtus.calib.board import board_from_spec
from virtus.calib.observe import observation_device
from virtus.calib.observers import (
    MAX_OBSERVE_PROCESSES,
    MAX_OBSERVE_THREADS,
    Observers,
    observe_threads,
    observe_timed,
    observer_pool,
    observers,
)
from virtus.calib.poses import pose_set
from virtus.calib.synthetic import board_image, projector_map
from virtus.errors import InputError
from virtus.scanner import Scanner

BOARD = board_from_spec("4x7")


def test_processes_argument_chooses_the_observers(monkeypatch):
    assert observers(None) == Observers("threads", observe_threads())
    assert observers(0) == Observers("here", 0) and observers(0).in_flight == 0
    assert observers(3) == Observers("processes", 3)
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert observe_threads() == 2
    monkeypatch.setattr("os.cpu_count", lambda: 64)
    assert observe_threads() == MAX_OBSERVE_THREADS
    monkeypatch.setattr("os.cpu_count", lambda: None)
    assert observe_threads() == 1
    for bad in (-1, MAX_OBSERVE_PROCESSES + 1, True, 2.0, "2"):
        with pytest.raises(InputError, match="processes"):
            observers(bad)  # type: ignore[arg-type]


def test_threads_observe_as_one_pose_after_the_other():
    rig = quarter_rig()
    camera = rig.camera.intrinsics
    views = []
    for pose in pose_set("random:4", rig, BOARD, 11):
        image = board_image(camera, BOARD, pose.board2cam, supersample=2)
        views.append((projector_map(rig, pose.board2cam), image, None, BOARD, pose.name))
    results = {}
    for chosen in (Observers("here", 0), Observers("threads", 3)):
        with observer_pool(chosen) as pool:
            jobs = [pool.submit(observe_timed, *view) for view in views]
            results[chosen.kind] = [job.result()[0] for job in jobs]
    for here, threads in zip(results["here"], results["threads"], strict=True):
        assert here.name == threads.name and here.cam_centroids is not None
        assert np.isfinite(here.cam_centroids).all()
        np.testing.assert_array_equal(threads.cam_centroids, here.cam_centroids)
        np.testing.assert_array_equal(threads.homographies, here.homographies)


def test_threads_fitting_on_a_torch_device_observe_the_host_fits():
    # What a calibration rendered on a GPU does (device "cuda"), with the CPU twin.
    pytest.importorskip("torch")
    rig = quarter_rig()
    pose = pose_set("random:1", rig, BOARD, 5)[0]
    image = board_image(rig.camera.intrinsics, BOARD, pose.board2cam, supersample=2)
    view = (projector_map(rig, pose.board2cam), image, None, BOARD, pose.name)
    with observer_pool(Observers("threads", 2)) as pool:
        host, device = (pool.submit(observe_timed, *view, device=d) for d in (None, "cpu"))
        host, device = host.result()[0], device.result()[0]
    assert np.isfinite(host.cam_centroids).all() and np.isfinite(host.homographies).all()
    np.testing.assert_allclose(device.cam_centroids, host.cam_centroids, rtol=0, atol=1e-9)
    np.testing.assert_allclose(device.homographies, host.homographies, rtol=1e-9, atol=1e-12)


def test_observation_device_is_cuda_only_for_poses_rendered_on_a_gpu(monkeypatch):
    torch = pytest.importorskip("torch")
    from virtus.calib import observe

    started = []
    monkeypatch.setattr(observe, "start_linear_algebra", started.append)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert observation_device(True) == "cuda" and observation_device(False) is None
    # torch's solvers are started on the device here, before any observer thread.
    assert started == ["cuda"]
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert observation_device(True) is None
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setitem(sys.modules, "torch", None)  # torch not installed
    assert observation_device(True) is None


def test_a_calibration_on_a_gpu_fits_in_its_threads_on_the_device(monkeypatch):
    # The pipeline passes observation_device's answer to every observing thread, and to no
    # spawned worker process.
    from virtus.pipeline import calibrate

    seen = []
    chosen = lambda on_gpu: seen.append(on_gpu) or "cuda:7"  # noqa: E731
    monkeypatch.setattr(calibrate, "observation_device", chosen)
    devices = []

    class Recording:
        def submit(self, function, *arguments, device=None):
            devices.append(device)
            raise RuntimeError("stop after the first pose")

    monkeypatch.setattr(
        calibrate, "observer_pool", lambda chosen: contextlib.nullcontext(Recording())
    )
    for processes, expected in ((None, "cuda:7"), (0, "cuda:7"), (2, None)):
        devices.clear()
        with pytest.raises(RuntimeError, match="stop after"):
            calibrate.calibrate_rig(Scanner(rig=quarter_rig()), board="4x7", processes=processes)
        assert devices == [expected]
    assert seen and not any(seen)  # this renderer is on the CPU
