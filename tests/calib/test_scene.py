"""The board's window in the camera image (:func:`virtus.calib.scene.board_window`): it
holds the board plane's whole image, lens distortion included, and no more than a margin
around it. The board's scene in each pose (:func:`virtus.calib.scene.board_scene`): the
plane and its texture checked once, each pose still checked, and no kernel compiled for a
new pose."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.calib.board import board_from_spec
from virtus.calib.poses import BoardPose
from virtus.calib.scene import board_scene, board_texture, board_window
from virtus.errors import InputError
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.scene.model import TexturedPlaneObject

BOARD = board_from_spec("7x13")
#: A 960 px camera with strong barrel distortion: edges bow out between the corners.
CAMERA = Intrinsics(1500.0, 1500.0, 479.5, 479.5, 960, 960, dist=(-0.4, 0.1, 0.0, 0.0))


def _plane_pixels(board2cam: Pose) -> np.ndarray:
    """Camera pixels of a dense grid over the whole board plane."""
    half = 0.5 * np.asarray(BOARD.plane_size_m)
    x, y = np.meshgrid(*(np.linspace(-h, h, 201) for h in half))
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    return CAMERA.project(board2cam.apply(points))


def test_the_window_holds_the_whole_board_image_and_a_margin():
    board2cam = Pose.from_euler("xyz", [25.0, -20.0, 10.0], t=(0.05, -0.03, 0.8))
    rows, cols = board_window(CAMERA, BOARD, board2cam, margin_px=8)
    pixels = _plane_pixels(board2cam)
    assert np.isfinite(pixels).all()
    lo, hi = pixels.min(axis=0), pixels.max(axis=0)
    assert cols.start <= lo[0] - 8 + 1 and hi[0] + 8 - 1 <= cols.stop - 1
    assert rows.start <= lo[1] - 8 + 1 and hi[1] + 8 - 1 <= rows.stop - 1
    assert cols.stop - cols.start <= hi[0] - lo[0] + 2 * 8 + 3  # no more than the margin
    # Near the image's edge the window is clipped to the image.
    side = Pose.from_euler("xyz", [0.0, 30.0, 0.0], t=(0.35, 0.0, 0.8))
    rows, cols = board_window(CAMERA, BOARD, side)
    assert cols.stop == CAMERA.width and rows.start > 0


def test_a_board_behind_the_camera_has_no_window():
    behind = Pose.from_euler("xyz", [0.0, 0.0, 0.0], t=(0.0, 0.0, -0.5))
    assert board_window(CAMERA, BOARD, behind) is None
    crossing = Pose.from_euler("xyz", [0.0, 89.0, 0.0], t=(0.0, 0.0, 0.05))
    assert board_window(CAMERA, BOARD, crossing) is None


def _texture() -> np.ndarray:
    texture = np.array(board_texture(BOARD), dtype=np.float64)
    texture.setflags(write=False)  # as the calibration keeps it
    return texture


def _pose(t: tuple[float, float, float], name: str = "p") -> BoardPose:
    return BoardPose(name, Pose.from_euler("xyz", [10.0, -5.0, 3.0], t=t))


def test_poses_of_one_board_share_its_checked_plane():
    texture = _texture()
    first, second = (board_scene(BOARD, _pose((0.0, 0.0, z)), texture) for z in (0.8, 0.9))
    plane, other = first.objects[0], second.objects[0]
    assert plane.texture is texture and other.texture is texture  # checked once, not copied
    built = TexturedPlaneObject(
        size_m=BOARD.plane_size_m, texture=texture, pose=_pose((0.0, 0.0, 0.9)).board2cam
    )
    assert other.pose == built.pose and other.size_m == built.size_m
    assert other.material == built.material and other.type == built.type
    assert other.model_fields_set == built.model_fields_set
    assert plane.pose.t[2] == 0.8 and other.pose.t[2] == 0.9


def test_each_pose_is_still_checked():
    with pytest.raises(InputError, match="pose"):
        board_scene(BOARD, _pose((0.0, 0.0, 1e9)), _texture())


def test_a_writeable_texture_is_checked_and_copied_in_every_pose():
    texture = np.array(board_texture(BOARD), dtype=np.float64)
    first = board_scene(BOARD, _pose((0.0, 0.0, 0.8)), texture).objects[0]
    texture[0, 0] = 0.5 if texture[0, 0] != 0.5 else 0.25
    second = board_scene(BOARD, _pose((0.0, 0.0, 0.8)), texture).objects[0]
    assert first.texture is not texture and second.texture is not texture
    assert second.texture[0, 0] == texture[0, 0] != first.texture[0, 0]
    texture[0, 0] = 2.0  # out of range: refused, not reused
    with pytest.raises(InputError, match="texture"):
        board_scene(BOARD, _pose((0.0, 0.0, 0.8)), texture)


def test_a_new_pose_compiles_no_kernel():
    """The calibration's GPU path (board scene, device render, decode on the device) on
    LLVM, with a small rig: after the first pose every kernel comes from Dr.Jit's
    in-memory cache (a per-pose value baked into a kernel's source would compile it
    again in every pose: 0.1-0.6 s a pose on 2 CPU cores)."""
    from virtus.calib.poses import pose_set
    from virtus.geometry.devices import Camera, Projector, Rig, default_rig
    from virtus.render import RenderSettings
    from virtus.render.backend import mitsuba
    from virtus.scanner import Scanner

    rig = default_rig()
    rig = Rig(
        Camera(rig.camera.intrinsics.scaled(0.25)),
        Projector(rig.projector.intrinsics.scaled(0.25)),
        rig.proj2cam,
    )
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1, variant="llvm_ad_rgb"))
    _, dr, _ = mitsuba("llvm_ad_rgb")
    texture = _texture()
    poses = pose_set("paper", rig, BOARD)[:3]
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        fresh = []
        for index, pose in enumerate(poses):
            dr.kernel_history()  # clears it
            view = scanner.decoded_view(
                board_scene(BOARD, pose, texture), rng=index, on_device=True
            )
            assert np.isfinite(view.decoded.proj_uv).any()
            kernels = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            assert kernels
            fresh.append(sum(k["cache_disk"] or not k["cache_hit"] for k in kernels))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert fresh[1:] == [0, 0]
