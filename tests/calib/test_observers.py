"""Where poses are observed (:mod:`virtus.calib.observers`): the choice made from a
calibration's ``processes`` argument, and threads observing poses side by side giving the
observations of one after the other (exact synthetic board views, no renderer)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.pipeline.test_calibrate_resume import quarter_rig
from virtus.calib.board import board_from_spec
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
