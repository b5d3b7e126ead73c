"""Renderer accuracy against independent references: Mitsuba's projector emitter, the
patterns decoder on a tilted plane, and the default sphere reconstructed with the true rig."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from tests.support import (
    LAMBERT,
    cropped_rig,
    fit_sphere_lsq,
    plane_depth,
    small_rig,
    sphere_and_plane,
    tilted_plane,
)
from virtus.geometry.devices import default_rig
from virtus.patterns import default_sequence
from virtus.reconstruct import points_from_decoded
from virtus.render import RenderSettings, render, synthesize, trace
from virtus.render.reference import ReferenceRenderer
from virtus.scene.model import Scene, default_scene
from virtus.sensor.projector import ProjectorModel


@pytest.fixture(scope="module")
def sequence():
    return default_sequence()


def frames_of_each_kind(sequence) -> list[int]:
    """A vertical and a horizontal phase frame, a Gray frame, a complement, white."""
    return [
        sequence.index_of("phase", "v", step=1, steps=18, period=18.0),
        sequence.index_of("phase", "h", step=7, steps=18, period=18.0),
        sequence.index_of("gray", "v", bit=3, bits=6, period=18.0),
        sequence.index_of("gray_complement", "h", period=18.0),
        sequence.index_of("white"),
    ]


@pytest.mark.parametrize("lookup", ["nearest", "bilinear"])
def test_agrees_with_mitsubas_projector_emitter(sequence, lookup: str) -> None:
    # Same rig (centred principal points, no distortion), diffuse sphere and plane, same
    # 2 x 2 sample positions (Mitsuba's stratified sampler without jitter).
    rig, scene = small_rig(), sphere_and_plane(LAMBERT)
    indices = frames_of_each_kind(sequence)
    ours = synthesize(trace(rig, scene, spp=4), sequence, lookup)[indices]
    mitsuba = ReferenceRenderer(rig, scene, spp=4, lookup=lookup, jitter=False)
    theirs = mitsuba.render_frames(sequence, indices)
    for k, index in enumerate(indices):
        mad = np.abs(ours[k] - theirs[k]).mean() / theirs[k].mean()
        assert mad < tol.MITSUBA_AGREEMENT_REL, (index, mad)


def test_matches_mitsuba_on_average_with_jittered_samples(sequence) -> None:
    # With Mitsuba's default (jittered) sampler, pixels differ by sampling noise only.
    rig, scene = small_rig(), sphere_and_plane(LAMBERT)
    indices = frames_of_each_kind(sequence)
    ours = synthesize(trace(rig, scene, spp=4), sequence, "bilinear")[indices]
    theirs = ReferenceRenderer(rig, scene, spp=4, lookup="bilinear").render_frames(
        sequence, indices, seed=3
    )
    for k in range(len(indices)):
        bias = abs((ours[k] - theirs[k]).mean()) / theirs[k].mean()
        assert bias < tol.MITSUBA_JITTERED_BIAS_REL, (indices[k], bias)


@pytest.fixture(scope="module")
def tilted_plane_decoded(sequence):
    """Decoded tilted-plane captures (nearest and bilinear), paper-sized camera pixels."""
    rig, plane = cropped_rig(320), tilted_plane()
    results = {}
    for lookup in ("nearest", "bilinear"):
        projector = ProjectorModel(pixel=lookup)
        rendering = render(
            rig, Scene([plane]), sequence, RenderSettings(spp=4), projector=projector
        )
        results[lookup] = (rendering, sequence.decode(rendering.frames, saturation_level=255))
    return rig, plane, results


def _rms_error(rendering, decoded) -> np.ndarray:
    valid = rendering.gt.mask & decoded.mask
    assert valid.mean() > tol.DECODE_VALID_FRACTION_MIN
    error = decoded.proj_uv[valid] - rendering.gt.proj_uv[valid]
    return np.sqrt(np.mean(error**2, axis=0))


def test_tilted_plane_decodes_to_ground_truth_with_bilinear_lookup(tilted_plane_decoded) -> None:
    _, _, results = tilted_plane_decoded
    rms = _rms_error(*results["bilinear"])
    assert np.all(rms < tol.DECODE_BILINEAR_RMS_PX), rms


def test_tilted_plane_nearest_lookup_shows_the_dmd_staircase(tilted_plane_decoded) -> None:
    _, _, results = tilted_plane_decoded
    rms = _rms_error(*results["nearest"])
    low, high = tol.NEAREST_STAIRCASE_RMS_PX
    assert np.all((rms > low) & (rms < high)), rms


def test_tilted_plane_depth_is_analytic(tilted_plane_decoded) -> None:
    rig, plane, results = tilted_plane_decoded
    gt = results["nearest"][0].gt
    assert gt.mask_hit.all()
    expected = plane_depth(rig.camera.intrinsics, plane)
    np.testing.assert_allclose(gt.depth, expected, atol=tol.PLANE_DEPTH_M, rtol=0)


@pytest.mark.slow
@pytest.mark.parametrize("lookup", ["nearest", "bilinear"])
def test_default_sphere_radius_from_decoded_frames(sequence, lookup: str) -> None:
    rig, scene = default_rig(), default_scene()
    rendering = render(rig, scene, sequence, projector=ProjectorModel(pixel=lookup))
    decoded = sequence.decode(rendering.frames, saturation_level=255)
    gt = rendering.gt
    on_sphere = gt.mask & (np.linalg.norm(gt.points - (0.0, 0.0, 1.0), axis=-1) < 0.1 + 1e-4)
    # Drop the one-pixel rim at the silhouette and shadow edges: there a pixel's supersamples
    # see both sphere and wall, a mixed signal (real "flying pixels", not a rendering error).
    padded = np.pad(on_sphere, 1)
    rim_free = np.ones_like(on_sphere)
    for dr in range(3):
        for dc in range(3):
            rim_free &= padded[dr : dr + on_sphere.shape[0], dc : dc + on_sphere.shape[1]]
    selected = rim_free & decoded.mask
    assert selected.sum() > 150_000
    points = points_from_decoded(rig, decoded.proj_uv, selected)[selected]
    centre, radius = fit_sphere_lsq(points)
    assert abs(radius - 0.1) < tol.SPHERE_RADIUS_M, radius
    np.testing.assert_allclose(centre, (0.0, 0.0, 1.0), atol=tol.SPHERE_CENTRE_DECODED_M)
