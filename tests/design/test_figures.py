"""The VDI/VDE 2634-2 figures on synthetic point maps with known answers, and the noise
range they are predicted by."""

from __future__ import annotations

import math

import numpy as np
import pytest

from virtus.design.figures import (
    EXCLUDED_FRACTION,
    expected_fit_bias,
    expected_form_range,
    measure_plane,
    measure_sphere,
    projector_jacobian,
    sphere_normals,
)
from virtus.errors import VirtusError
from virtus.geometry.devices import default_rig
from virtus.geometry.transforms import Pose

RIG = default_rig()
CENTRE = np.array([0.01, -0.02, 1.0])
RADIUS = 0.04


def _sphere_map(bump: np.ndarray | None = None, size: int = 80) -> np.ndarray:
    """(size, size, 3) point map of the visible cap of a sphere, radially displaced by
    ``bump`` (size, size) metres, NaN off the sphere."""
    v, u = np.mgrid[0:size, 0:size].astype(float)
    grid = np.stack([u, v], axis=-1).reshape(-1, 2)
    # a camera whose 80 x 80 px see the sphere: rays through a 0.1 x 0.1 window at 1 m
    rays = np.concatenate(
        [(grid - size / 2 + 0.5) * (0.1 / size) + CENTRE[:2], np.ones((grid.shape[0], 1))], 1
    )
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    b = rays @ CENTRE
    disc = b * b - (CENTRE @ CENTRE - RADIUS**2)
    with np.errstate(invalid="ignore"):
        points = rays * (b - np.sqrt(disc))[:, None]
    if bump is not None:
        normal = (points - CENTRE) / RADIUS
        points = points + normal * bump.reshape(-1, 1)
    return points.reshape(size, size, 3)


def test_sphere_form_and_size_are_the_planted_ones():
    exact = measure_sphere(_sphere_map(), CENTRE, RADIUS)
    assert exact.diameter_m == pytest.approx(2 * RADIUS, abs=1e-12)
    assert exact.form_m < 1e-12
    np.testing.assert_allclose(exact.centre_m, CENTRE, atol=1e-12)
    # +-20 um of pixel-to-pixel radial ripple: P_F is its range
    v, u = np.mgrid[0:80, 0:80]
    ripple = np.where((u + v) % 2 == 0, 20e-6, -20e-6)  # a checkerboard: the fit ignores it
    fit = measure_sphere(_sphere_map(ripple), CENTRE, RADIUS)
    assert fit.form_m == pytest.approx(40e-6, rel=0.03)  # the fit leans ~1 um into it
    assert abs(fit.diameter_m - 2 * RADIUS) < 2e-6


def test_up_to_0_3_percent_of_the_points_are_left_out():
    points = _sphere_map()
    n = int(np.isfinite(points).all(axis=-1).sum())
    allowed = math.floor(EXCLUDED_FRACTION * n)
    spikes = np.zeros(points.shape[:2])
    rows, cols = np.nonzero(np.isfinite(points).all(axis=-1))
    spikes[rows[:allowed], cols[:allowed]] = 1e-3  # outliers the guideline may drop
    fit = measure_sphere(_sphere_map(spikes), CENTRE, RADIUS)
    assert fit.n_excluded == allowed and fit.form_m < 1e-9
    spikes[rows[allowed], cols[allowed]] = 1e-3  # one more than allowed stays in
    fit = measure_sphere(_sphere_map(spikes), CENTRE, RADIUS)
    assert fit.form_m > 0.9e-3


def test_a_sphere_not_seen_is_an_error_naming_it():
    with pytest.raises(VirtusError, match="ball_bar_03"):
        measure_sphere(_sphere_map(), CENTRE + [0.5, 0, 0], RADIUS, "ball_bar_03")


def test_plane_flatness_is_the_planted_roughness():
    pose = Pose.look_at((0.0, 0.0, 0.0), (0.3, 0.1, 1.0))  # any tilt
    x, y = np.meshgrid(np.linspace(-0.1, 0.1, 60), np.linspace(-0.03, 0.03, 20))
    i, j = np.indices(x.shape)
    step = np.where((i + j) % 2 == 0, 15e-6, -15e-6)  # orthogonal to any tilt
    local = np.stack([x, y, step], axis=-1).reshape(-1, 3)
    points = pose.apply(local).reshape(20, 60, 3)
    fit = measure_plane(points, pose, (0.2, 0.06))
    assert fit.flatness_m == pytest.approx(30e-6, rel=0.02)  # likewise, ~0.4 um
    assert abs(fit.normal @ pose.R[:, 2]) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(("n", "d2"), [(2, 1.128), (5, 2.326), (10, 3.078), (25, 3.931)])
def test_expected_range_of_normal_draws_matches_the_tabulated_constants(n, d2):
    """The mean range of n standard normals (the d2 constants of control charts); no point
    is left out below 334 points."""
    assert expected_form_range(np.full(n, 2.0), trials=5000) == pytest.approx(2.0 * d2, rel=0.02)


def test_projector_jacobian_moves_the_point_along_its_camera_ray():
    """At the sphere's true correspondences, dX/du_p and dX/dv_p lie (nearly) along the
    camera ray: triangulation keeps the camera pixel, so a projector error is a depth error
    (the ray-ray midpoint strays from it by a few degrees at most)."""
    cam_px = np.array([[480.0, 480.0], [300.0, 600.0], [560.0, 400.0]])
    points, normals, proj_uv = sphere_normals(RIG, cam_px, (0.0, 0.0, 1.0), 0.1)
    jac = projector_jacobian(RIG, cam_px, proj_uv)
    rays = points / np.linalg.norm(points, axis=1, keepdims=True)
    for j in range(2):
        col = jac[:, :, j]
        along = np.abs(np.einsum("ni,ni->n", col, rays)) / np.linalg.norm(col, axis=1)
        assert (along > 0.95).all()
    # one projector px of u_p is ~3 mm of depth at 1 m for this rig (f_p 1824 px, 9 deg)
    assert 1e-3 < np.linalg.norm(jac[0, :, 0]) < 5e-3


def _seen(centre: np.ndarray, radius: float) -> np.ndarray:
    """Every other camera pixel of the paper's 960 px camera that sees the sphere."""
    v, u = np.mgrid[0:960:2, 0:960:2]
    cam_px = np.stack([u.ravel(), v.ravel()], axis=1).astype(float)
    points, _, _ = sphere_normals(RIG, cam_px, centre, radius)
    return cam_px[np.isfinite(points).all(axis=1)]


def test_the_sphere_fit_is_biased_small_by_the_variance_of_the_coordinate_errors():
    """Errors in variables: zero-mean projector-coordinate errors make the geometric sphere fit
    smaller (P_S < 0) with its centre nearer the camera, as their variance grows (measured:
    -0.018 / -0.067 / -0.149 mm for 0.1 / 0.2 / 0.3 px on this 80 mm sphere), and not at all
    without errors."""
    cam_px = _seen(CENTRE, RADIUS)
    exact, shift = expected_fit_bias(RIG, cam_px, CENTRE, RADIUS, 0.0, trials=1)
    assert abs(exact) < 1e-9 and np.abs(shift).max() < 1e-9
    small, shift_small = expected_fit_bias(RIG, cam_px, CENTRE, RADIUS, 0.1)
    large, shift_large = expected_fit_bias(RIG, cam_px, CENTRE, RADIUS, 0.2)
    assert large < small < -5e-6  # metres of diameter
    assert large / small == pytest.approx(4.0, rel=0.15)  # the variance, not the sigma
    assert shift_large[2] < shift_small[2] < 0  # toward the camera
    assert shift_large[2] == pytest.approx(0.8 * large, rel=0.25)  # a cap's size and depth
