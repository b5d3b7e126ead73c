"""The batched window fit's trimming (:mod:`virtus.calib.windowfit`): the row medians it
trims by, on numpy and on torch (the device path's CPU twin). The fits themselves are
tested through :func:`virtus.calib.projector.local_homographies`
(``tests/calib/test_projector.py``)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from virtus.calib import arrayspace, windowfit


def test_row_medians_of_degenerate_fits_are_nan_without_a_warning():
    # Windows are fitted in observer threads, where silencing np.nanmedian's all-NaN
    # warning with warnings.catch_warnings would race on the process's warning filters.
    residual = np.array([[1.0, np.nan, 3.0, 2.0], [np.nan] * 4, [0.5, 0.5, np.nan, np.nan]])
    filters = list(warnings.filters)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        median = windowfit._row_medians(arrayspace.NUMPY, residual)
    np.testing.assert_array_equal(median, [[2.0], [np.nan], [0.5]])
    assert warnings.filters == filters


def test_torch_row_medians_are_numpys_nanmedian():
    torch = pytest.importorskip("torch")

    residual = np.array([[1.0, np.nan, 3.0, 2.0], [np.nan] * 4, [0.5, 0.7, np.nan, np.nan]])
    space = arrayspace.torch_space("cpu")
    median = windowfit._row_medians(space, torch.as_tensor(residual))
    # The mean of the two middle values for an even count, as np.nanmedian (torch's own
    # nanmedian takes the lower one).
    np.testing.assert_array_equal(median.numpy(), [[2.0], [np.nan], [0.6]])
