"""The metrics module (virtus.learn.metrics): exact sums on hand-made maps, the wrap band,
the flat-plane RMS, and missing predictions counted as missing."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.learn.metrics import WRAP_BAND_RAD, MetricSums, plane_rms, sample_errors, wrap_to_pi


def test_depth_errors_split_objects_and_background() -> None:
    depth = np.full((4, 5), 2.0)
    surface = np.ones((4, 5), bool)
    surface[0, 0] = False
    objects = np.zeros((4, 5), bool)
    objects[1:3, 1:3] = True
    pred = depth.copy()
    pred[1, 1] += 0.004  # object: errors 4, -2, 0, 0 mm
    pred[1, 2] -= 0.002
    pred[3, 4] += 0.010  # background: one 10 mm error over 15 pixels
    pred[0, 1] = np.nan  # a background pixel without prediction: missing, not an error
    sums = MetricSums()
    sums.add(sample_errors(pred, depth, surface, objects))
    out = sums.summary()
    assert out["object_mae_mm"] == pytest.approx(6 / 4)
    assert out["object_rmse_mm"] == pytest.approx(np.sqrt(20 / 4))
    assert out["background_mae_mm"] == pytest.approx(10 / 14)
    assert out["valid_share"] == pytest.approx(18 / 19)
    assert out["phase_rmse_rad"] is None and out["flat_rms_mm"] is None


def test_phase_errors_order_and_wrap_band() -> None:
    wrapped = np.array([[0.0, np.pi - WRAP_BAND_RAD / 2, -np.pi + 0.01, 1.0]])
    valid = np.ones_like(wrapped, bool)
    # a prediction 0.02 rad across the wrap is 0.02 rad off, not 2 pi - 0.02
    pred = wrap_to_pi(wrapped + np.array([[0.1, 0.0, -0.02, 0.0]]))
    order = np.array([[3, 3, 4, 5]])
    pred_order = np.array([[3, 3, 3, 5]])  # the wrap pixel got the wrong order
    depth = np.ones_like(wrapped)
    pred_depth = depth + np.array([[0.0, 0.0, 0.05, 0.001]])
    errors = sample_errors(pred_depth, depth, valid, valid, pred_wrapped=pred, wrapped=wrapped,
                           pred_order=pred_order, order=order, valid=valid)  # fmt: skip
    sums = MetricSums()
    sums.add(errors)
    out = sums.summary()
    assert out["phase_rmse_rad"] == pytest.approx(np.sqrt((0.1**2 + 0.02**2) / 4))
    assert out["order_error_rate"] == pytest.approx(0.25)
    assert out["wrap_share"] == pytest.approx(0.5)
    assert out["wrap_mae_mm"] == pytest.approx(25.0)
    assert out["nonwrap_mae_mm"] == pytest.approx(0.5)


def test_flat_plane_rms() -> None:
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.5, 0.5, (500, 2))
    plane = np.column_stack([xy, 2.0 + 0.3 * xy[:, 0] - 0.1 * xy[:, 1]])
    assert plane_rms(plane) < 1e-12
    bumpy = plane.copy()
    bumpy[:, 2] += 0.01 * np.sign(xy[:, 0])  # a step of 20 mm: RMS 10 mm about the best plane
    assert 0.004 < plane_rms(bumpy) < 0.011
    assert plane_rms(plane[:2]) is None
    # through sample_errors: planes-only samples (no object pixel) give flat_rms_mm
    v, u = np.mgrid[0:20, 0:30].astype(float)
    rays = np.stack([(u - 15) / 50, (v - 10) / 50, np.ones_like(u)], axis=-1)
    depth = 1.5 / (1 - 0.2 * rays[..., 0])  # the plane Z = 1.5 + 0.2 X
    surface = np.ones(depth.shape, bool)
    flat = sample_errors(depth, depth, surface, ~surface, rays=rays)
    bump = depth + 0.005 * (u > 15)
    bumped = sample_errors(bump, depth, surface, ~surface, rays=rays)
    assert flat["flat_rms_mm"] < 1e-6 and bumped["flat_rms_mm"] > 1.0
    assert "flat_rms_mm" not in sample_errors(depth, depth, surface, surface, rays=rays)
