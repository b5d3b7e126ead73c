"""Local camera -> projector homographies around the board points
(:mod:`virtus.calib.projector`): the batched fit (one normalised DLT + Gauss-Newton for
all circles, gross errors trimmed) against the per-circle ``cv2.findHomography`` path it
replaced, on a rendered board and on maps built here from known homographies (seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.pipeline.test_calibrate_resume import quarter_rig
from virtus.calib import projector, windowfit
from virtus.calib.board import board_from_spec
from virtus.calib.detect import find_grid
from virtus.calib.poses import pose_set
from virtus.calib.projector import (
    apply_homographies,
    local_homographies,
    local_homographies_per_circle,
)
from virtus.calib.scene import board_scene, board_texture
from virtus.render import RenderSettings
from virtus.scanner import Scanner

BOARD = board_from_spec("4x7")
#: Batched vs per-circle projector points. The two fits minimise the same transfer error
#: over inlier sets that differ only in pixels near the threshold (RANSAC's from a
#: 4-point hypothesis, the trimmed set's from the least-squares fit): measured up to
#: 1.2e-4 px on the paper's 960 px poses; 1e-3 px is still 5x below the projector
#: points' own error (~0.005 px RMS) and fails on any formula or inlier error.
AGREE_PX = 1e-3
#: Points from an exact homography map (no noise): float64 rounding of the batched fit
#: (measured < 1e-8 px); cv2's refinement stops at its own tolerance (measured 4e-7 px).
EXACT_PX = 1e-7
CV2_EXACT_PX = 1e-5


@pytest.fixture(scope="module")
def rendered() -> tuple[np.ndarray, np.ndarray]:
    """Decoded projector coordinates (240 x 240 px) of one rendered 4x7 board pose (default
    phase sequence, 1 spp) and the detected circle centres."""
    rig = quarter_rig()
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    pose = pose_set("random:1", rig, BOARD, 3)[0]
    view = scanner.decoded_view(board_scene(BOARD, pose, board_texture(BOARD)), rng=0)
    centres = find_grid(view.white if view.white is not None else view.decoded.background, BOARD)
    assert centres is not None
    return view.decoded.proj_uv, centres


def points(homographies: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Projector points at a fixed sub-pixel offset from the centres."""
    return apply_homographies(homographies, centres + 0.3)


def test_batched_fit_gives_the_per_circle_points_on_a_rendered_board(rendered):
    proj_uv, centres = rendered
    batched = points(local_homographies(proj_uv, BOARD, centres), centres)
    reference = points(local_homographies_per_circle(proj_uv, BOARD, centres), centres)
    assert np.isfinite(reference).all()
    assert np.max(np.linalg.norm(batched - reference, axis=1)) < AGREE_PX


@pytest.mark.parametrize("fraction", [0.1, 0.3])
def test_gross_decoding_errors_are_trimmed_like_ransac(rendered, fraction):
    proj_uv, centres = rendered
    rng = np.random.default_rng(7)
    corrupted = proj_uv.copy()
    hit = rng.random(proj_uv.shape[:2]) < fraction
    corrupted[hit] += rng.uniform(-80.0, 80.0, (int(hit.sum()), 2))
    batched = points(local_homographies(corrupted, BOARD, centres), centres)
    reference = points(local_homographies_per_circle(corrupted, BOARD, centres), centres)
    clean = points(local_homographies(proj_uv, BOARD, centres), centres)
    assert np.isfinite(batched).all()
    assert np.max(np.linalg.norm(batched - reference, axis=1)) < AGREE_PX
    # Without trimming, 10 % of +-80 px errors would move the points by pixels.
    assert np.max(np.linalg.norm(batched - clean, axis=1)) < 0.05


def synthetic_map(
    shape: tuple[int, int] = (200, 240), stripe: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A board seen through a board (m) -> camera px homography and a camera -> projector
    homography over every pixel (rounded to ``stripe``-wide stripe centres when given):
    the map, the circle centres (camera px) and the true homography."""
    board2cam = np.array([[900.0, 40.0, 118.0], [-30.0, 880.0, 101.0], [0.2, 0.3, 1.0]])
    cam2proj = np.array([[1.1, 0.05, 20.0], [-0.04, 1.2, 9.0], [1e-4, -2e-4, 1.0]])
    obj = np.column_stack([BOARD.object_points[:, :2], np.ones(BOARD.n_points)])
    centres = obj @ board2cam.T
    centres = centres[:, :2] / centres[:, 2:]
    vv, uu = np.mgrid[0 : shape[0], 0 : shape[1]]
    pix = np.stack([uu, vv, np.ones_like(uu)], axis=-1).astype(np.float64)
    uv = pix @ cam2proj.T
    uv = uv[..., :2] / uv[..., 2:]
    if stripe is not None:
        uv = (np.floor(uv / stripe) + 0.5) * stripe
    return uv, centres, cam2proj


def truth(cam2proj: np.ndarray, centres: np.ndarray) -> np.ndarray:
    return apply_homographies(np.repeat(cam2proj[None], len(centres), axis=0), centres + 0.3)


def test_exact_homography_map_is_recovered_and_batches_do_not_change_it(monkeypatch):
    uv, centres, cam2proj = synthetic_map()
    whole = local_homographies(uv, BOARD, centres)
    assert np.max(np.abs(points(whole, centres) - truth(cam2proj, centres))) < EXACT_PX
    reference = points(local_homographies_per_circle(uv, BOARD, centres), centres)
    assert np.max(np.abs(reference - truth(cam2proj, centres))) < CV2_EXACT_PX
    np.testing.assert_allclose(whole[:, 2, 2], 1.0)
    monkeypatch.setattr(projector, "_BATCH_PIXELS", 1)  # one circle a batch
    # Other padding sums in another order: rounding only.
    np.testing.assert_allclose(
        local_homographies(uv, BOARD, centres), whole, rtol=1e-12, atol=1e-12
    )


def test_stripe_centres_agree_with_the_per_circle_fit():
    uv, centres, cam2proj = synthetic_map(stripe=2.0)
    batched = points(local_homographies(uv, BOARD, centres, stripe=2.0), centres)
    reference = points(local_homographies_per_circle(uv, BOARD, centres, stripe=2.0), centres)
    assert np.max(np.linalg.norm(batched - reference, axis=1)) < AGREE_PX
    assert np.max(np.linalg.norm(batched - truth(cam2proj, centres), axis=1)) < 0.1


def test_a_circle_without_enough_decoded_pixels_is_nan_in_both_fits():
    uv, centres, _ = synthetic_map()
    vv, uu = np.mgrid[0 : uv.shape[0], 0 : uv.shape[1]]
    hole = np.hypot(uu - centres[5, 0], vv - centres[5, 1]) < 30
    uv[hole] = np.nan
    for fit in (local_homographies, local_homographies_per_circle):
        homographies = fit(uv, BOARD, centres)
        lost = ~np.isfinite(homographies).all(axis=(1, 2))
        assert lost[5] and lost.sum() < BOARD.n_points
        np.testing.assert_array_equal(np.isnan(homographies).all(axis=(1, 2)), lost)
    batched = local_homographies(uv, BOARD, centres)
    reference = local_homographies_per_circle(uv, BOARD, centres)
    np.testing.assert_array_equal(np.isnan(batched[:, 0, 0]), np.isnan(reference[:, 0, 0]))
    off_image = centres + 1e4  # every window off the image: all NaN, no error
    assert np.isnan(local_homographies(uv, BOARD, off_image)).all()


@pytest.fixture(scope="module")
def torch_cpu() -> str:
    """The torch device of the fit's CPU twin (a CUDA device fits with the same code)."""
    pytest.importorskip("torch")
    return "cpu"


@pytest.mark.parametrize("case", ["rendered", "corrupted", "stripes", "holes"])
def test_torch_fit_gives_the_numpy_fit(rendered, torch_cpu, case):
    # The device path runs this same code on CUDA tensors; torch on the CPU is its twin.
    if case == "stripes":
        proj_uv, centres, _ = synthetic_map(stripe=2.0)
    elif case == "holes":
        proj_uv, centres, _ = synthetic_map()
        vv, uu = np.mgrid[0 : proj_uv.shape[0], 0 : proj_uv.shape[1]]
        proj_uv[np.hypot(uu - centres[5, 0], vv - centres[5, 1]) < 30] = np.nan
    else:
        proj_uv, centres = rendered
    if case == "corrupted":
        rng = np.random.default_rng(3)
        proj_uv = proj_uv.copy()
        hit = rng.random(proj_uv.shape[:2]) < 0.3
        proj_uv[hit] += rng.uniform(-80.0, 80.0, (int(hit.sum()), 2))
    stripe = 2.0 if case == "stripes" else None
    host = local_homographies(proj_uv, BOARD, centres, stripe=stripe)
    twin = local_homographies(proj_uv, BOARD, centres, stripe=stripe, device=torch_cpu)
    lost = np.isnan(host).all(axis=(1, 2))
    np.testing.assert_array_equal(np.isnan(twin).all(axis=(1, 2)), lost)
    assert (lost[5] and lost.sum() < BOARD.n_points) if case == "holes" else not lost.any()
    moved = np.linalg.norm(points(twin, centres) - points(host, centres), axis=1)
    assert np.nanmax(moved) < 1e-9  # rounding: the same inliers, the same formulas


def test_torch_fit_batches_a_whole_pose_at_once(torch_cpu, monkeypatch):
    uv, centres, cam2proj = synthetic_map()
    calls = []
    fit = windowfit.fit_windows
    monkeypatch.setattr(projector, "fit_windows", lambda *a: calls.append(len(a[1])) or fit(*a))
    twin = local_homographies(uv, BOARD, centres, device=torch_cpu)
    assert calls == [BOARD.n_points]
    assert np.max(np.abs(points(twin, centres) - truth(cam2proj, centres))) < EXACT_PX
