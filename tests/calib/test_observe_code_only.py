"""Observing board poses from codes alone (no phase frames): OpenCV's ``GrayCodePattern`` or
a plain binary code decodes to integer projector columns and rows (stripe centres), which
the local homographies around each board point turn into sub-pixel projector points (Moreno
& Taubin 2012); the board's points are refined on the mean of the code's pattern/inverse
pairs and white and black (:func:`virtus.calib.observe.uniform_image`)."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from tests.pipeline.test_calibrate_resume import quarter_rig
from virtus.calib.board import board_from_spec
from virtus.calib.observe import check_sequence, observe_pose, uniform_image
from virtus.calib.poses import pose_set
from virtus.calib.projector import apply_homographies
from virtus.calib.scene import (
    board_scene,
    board_texture,
)
from virtus.errors import InputError
from virtus.patterns import PatternSequence, default_sequence, opencv_graycode_sequence
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.sensor.camera import SENSOR_PRESETS
from virtus.sensor.projector import PROJECTOR_PRESETS

#: 240 x 240 camera, 228 x 285 projector (a projector pixel ~1.25 camera pixels on the board).
RIG = quarter_rig()


def code_sequence(
    code: str, width: int, height: int, *, bits: int | None = None, inverted: bool = True
) -> PatternSequence:
    """Both directions coded alone, most significant bit first (a word per projector pixel
    by default), each bit then its inverse when ``inverted``, white and black last."""
    blocks = [
        {"kind": code, "direction": direction, "bits": bits or (span - 1).bit_length()}
        | {"inverted": inverted}
        for direction, span in (("v", width), ("h", height))
    ]
    blocks += [{"kind": "white"}, {"kind": "black"}]
    return PatternSequence.from_dict({"width": width, "height": height, "blocks": blocks})


def sequence_of(code: str, bits: int | None = None) -> PatternSequence:
    projector = RIG.projector.intrinsics
    if code == "opencv":
        return opencv_graycode_sequence(projector.width, projector.height)
    return code_sequence(code, projector.width, projector.height, bits=bits)


def projector_point_errors(
    sequence: PatternSequence, spec: str, poses: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """Projector points of a rendered board (imx174 sensor, LightCrafter-class projector:
    blurred pixels, gamma, 1000:1) from its observation's local homographies, evaluated at
    the true camera points, minus the true projector points; and the same read from the
    decoded map at the nearest camera pixel (what a homography averages away)."""
    board = board_from_spec(spec)
    texture = board_texture(board)
    scanner = Scanner(
        rig=RIG,
        sequence=sequence,
        sensor=SENSOR_PRESETS["imx174"],
        projector=PROJECTOR_PRESETS["lightcrafter"],
        render=RenderSettings(spp=1),
    )
    camera, projector = RIG.camera.intrinsics, RIG.projector.intrinsics
    errors, naive = [], []
    for index, pose in enumerate(pose_set(f"random:{poses}", RIG, board, 1)):
        capture = scanner.capture(board_scene(board, pose, texture), rng=index)
        observation = observe_pose(capture, board, pose.name)
        assert observation.problem() is None, observation.problem()
        points = pose.board2cam.apply(board.object_points)
        cam_points = camera.project(points)
        truth = projector.project(RIG.cam2proj.apply(points))
        errors.append(apply_homographies(observation.homographies, cam_points) - truth)
        nearest = np.rint(cam_points).astype(int)
        naive.append(capture.decode().proj_uv[nearest[:, 1], nearest[:, 0]] - truth)
    return np.concatenate(errors), np.concatenate(naive)


# -- the sequence check ------------------------------------------------------------------


def test_codes_alone_in_both_directions_calibrate_and_one_direction_is_refused():
    check_sequence(opencv_graycode_sequence(228, 285))
    check_sequence(code_sequence("binary", 228, 285))
    check_sequence(code_sequence("binary", 228, 285, inverted=False))
    one = PatternSequence.from_dict(
        {
            "width": 228,
            "height": 285,
            "blocks": [
                {"kind": "gray", "direction": "v", "bits": 8, "inverted": True},
                {"kind": "white"},
                {"kind": "black"},
            ],
        }
    )
    with pytest.raises(InputError, match=r"^sequence: expected phase frames in both") as error:
        check_sequence(one)
    assert "Gray or binary code alone in both" in str(error.value)
    assert "\n" not in str(error.value)


# -- the board under uniform light -------------------------------------------------------


def test_uniform_image_is_the_mean_of_the_pairs_white_and_black():
    sequence = opencv_graycode_sequence(16, 8)  # 4 + 3 bit pairs, white, black: 16 frames
    kinds = [frame.kind for frame in sequence.frames]
    rng = np.random.default_rng(4)
    shape = (64, 64)
    white, black = rng.uniform(500.0, 3000.0, shape), np.full(shape, 40.0)
    clean = np.empty((len(sequence), *shape))
    clean[kinds.index("white")], clean[kinds.index("black")] = white, black
    for plan in sequence.plans().values():
        for normal, inverse in zip(plan.code.normal, plan.code.inverse, strict=True):
            lit = rng.uniform(0.0, 1.0, shape)  # stripe edges: any share of the pixel lit
            clean[normal] = black + (white - black) * lit
            clean[inverse] = black + (white - black) * (1.0 - lit)
    truth = 0.5 * (white + black)
    np.testing.assert_allclose(uniform_image(clean, sequence, truth * 0), truth, rtol=1e-12)
    sigma = 20.0
    noisy = clean + rng.normal(0.0, sigma, clean.shape)
    two = 0.5 * (noisy[kinds.index("white")] + noisy[kinds.index("black")])
    pairs = 7 + 1  # the code's pairs and white + black
    ratio = np.std(uniform_image(noisy, sequence, two) - truth) / np.std(two - truth)
    assert ratio == pytest.approx(1 / np.sqrt(pairs), rel=tol.CODE_ONLY_UNIFORM_NOISE_REL)
    # phase frames: the decoded background as it is
    background = np.ones((4, 4))
    phase = default_sequence(16, 8)
    assert uniform_image(np.zeros((len(phase), 4, 4)), phase, background) is background
    # single code frames (no inverse): white and black alone
    single = code_sequence("binary", 16, 8, inverted=False)
    frames = rng.uniform(0.0, 4095.0, (len(single), 4, 4))
    uniform = [frame.kind for frame in single.frames]
    expected = 0.5 * (frames[uniform.index("white")] + frames[uniform.index("black")])
    np.testing.assert_allclose(uniform_image(frames, single, background), expected, rtol=1e-12)


# -- projector points from codes alone ---------------------------------------------------


@pytest.mark.parametrize("spec", ["4x7", "checker:6x9,square_mm=20"])
@pytest.mark.parametrize("code", ["opencv", "binary"])
def test_codes_alone_give_sub_pixel_projector_points(code, spec):
    """Integer stripe centres, noisy camera, blurred projector pixels: the local homographies
    still place every board point in the projector within a hundredth of a pixel, ~50 times
    closer than the decoded map read at the point."""
    errors, naive = projector_point_errors(sequence_of(code), spec)
    assert np.isfinite(errors).all()
    assert np.abs(errors.mean(axis=0)).max() <= tol.CODE_ONLY_POINT_BIAS_PX
    rms = np.sqrt(np.mean(errors**2))
    assert rms <= tol.CODE_ONLY_POINT_RMS_PX
    assert rms <= np.sqrt(np.nanmean(naive**2)) / tol.CODE_ONLY_NAIVE_FACTOR


def test_wide_stripes_keep_every_board_point():
    """A 6-bit Gray code over 228 px (3.6 px stripes): the RANSAC threshold follows the
    stripe width (at 1 px every circle was lost)."""
    sequence = sequence_of("gray", bits=6)
    errors, _ = projector_point_errors(sequence, "4x7")
    assert np.isfinite(errors).all()
    assert np.sqrt(np.mean(errors**2)) <= tol.CODE_ONLY_WIDE_STRIPE_RMS_PX
