"""numpy arrays or torch tensors (:mod:`virtus.calib.arrayspace`): every operation whose
spelling differs gives torch's tensors numpy's answer (torch on the CPU: the device path's
twin), and torch's solvers start from one thread."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.calib.arrayspace import NUMPY, space_of, start_linear_algebra


@pytest.fixture(scope="module")
def torch_cpu():
    """The torch space on the CPU (a CUDA device runs the same operations)."""
    pytest.importorskip("torch")
    return space_of("cpu")


def test_space_of_nothing_is_numpy() -> None:
    assert space_of(None) is NUMPY and NUMPY.xp is np


def test_each_operation_gives_numpys_answer_on_torch(torch_cpu) -> None:
    values = np.array([[1.0, np.nan, 3.0, 2.0], [4.0, 5.0, np.nan, np.nan], [7.0, 0.5, 6.0, 1.0]])
    for space in (NUMPY, torch_cpu):
        on = space.asarray(values)
        assert space.to_host(on).dtype == np.float64
        np.testing.assert_array_equal(space.to_host(space.row_medians(on)), [[2.0], [4.5], [3.5]])
        finite = space.asarray(np.nan_to_num(values, nan=-1.0))
        np.testing.assert_array_equal(space.to_host(space.row_max(finite)), [3.0, 5.0, 7.0])
        full, eye = space.full((2, 3), 0.25), space.eye(3)
        np.testing.assert_array_equal(space.to_host(full), np.full((2, 3), 0.25))
        np.testing.assert_array_equal(space.to_host(eye), np.eye(3))
        flags = space.to_host(space.float64(space.asarray(np.array([True, False]))))
        assert flags.dtype == np.float64 and flags.tolist() == [1.0, 0.0]
        copy = space.copy(on)
        copy[0, 0] = 9.0
        assert space.to_host(on)[0, 0] == 1.0  # a copy, not a view
        assert space.equal(on[2], on[2]) and not space.equal(on[2], on[2] + 1.0)
        with space.quiet():
            assert np.isinf(space.to_host(space.asarray(np.array([1.0])) / 0.0)).all()
        with pytest.raises(space.singular_error):
            space.xp.linalg.solve(space.full((3, 3), 0.0), space.eye(3))


def test_linear_algebra_starts_on_a_device(torch_cpu) -> None:
    # What the observers' thread runs on "cuda" before they start (pytorch/pytorch#90613).
    start_linear_algebra("cpu")
