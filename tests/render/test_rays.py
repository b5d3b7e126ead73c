"""Camera ray directions (:mod:`virtus.render.rays`): rows laid out for the kernels."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError
from virtus.render.rays import ROW_ALIGN, aligned_rows, sample_offsets


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n", [1, 7, 25_500])
def test_aligned_rows_copy_the_values_with_every_row_aligned(dtype, n) -> None:  # noqa: ANN001
    values = np.arange(3 * n, dtype=dtype).reshape(3, n)
    rows = aligned_rows(values)
    np.testing.assert_array_equal(rows, values)
    assert rows.dtype == dtype and not rows.flags.writeable
    assert all(row.ctypes.data % ROW_ALIGN == 0 for row in rows)


@pytest.mark.parametrize("spp", [1, 4, 9, 16])
def test_sample_offsets_are_a_grid_centred_on_the_pixel(spp: int) -> None:
    offsets = sample_offsets(spp)
    side = int(np.sqrt(spp))
    assert offsets.shape == (spp, 2)
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=tol.SAMPLE_OFFSET_MEAN_PX)
    np.testing.assert_allclose(np.unique(offsets[:, 0]), (np.arange(side) + 0.5) / side - 0.5)
    if spp == 4:
        np.testing.assert_allclose(np.abs(offsets), 0.25)


@pytest.mark.parametrize("spp", [0, 2, 3, 5, 8, 2.5])
def test_spp_must_be_a_perfect_square(spp: object) -> None:
    with pytest.raises(InputError, match="spp"):
        sample_offsets(spp)
