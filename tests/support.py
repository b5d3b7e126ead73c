"""Shared builders for the renderer tests (small rigs and scenes, sphere fit)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.scene.model import Material, PlaneObject, Scene, SphereObject

#: Lambertian (Mitsuba "diffuse") material used where closed forms are needed.
LAMBERT = Material(albedo=0.8, specular=0.0)


def small_rig(factor: float = 1 / 6) -> Rig:
    """The default rig with its camera resampled (160 x 160 px for 1/6): fast, and still
    centred, so Mitsuba's symmetric frusta can render it too."""
    rig = default_rig()
    return Rig(Camera(rig.camera.intrinsics.scaled(factor)), rig.projector, rig.proj2cam)


def cropped_rig(size: int = 320) -> Rig:
    """The default rig with the camera cropped to ``size`` x ``size`` px around its centre:
    the same pixel footprint on the object as the paper's camera (claims about camera vs
    projector pixel sizes hold), fewer pixels."""
    rig = default_rig()
    k = rig.camera.intrinsics
    camera = Intrinsics(k.fx, k.fy, (size - 1) / 2, (size - 1) / 2, size, size)
    return Rig(Camera(camera), rig.projector, rig.proj2cam)


def sphere_and_plane(material: Material = LAMBERT) -> Scene:
    """The default scene's geometry with one material everywhere."""
    return Scene(
        objects=[SphereObject(0.1, (0.0, 0.0, 1.0), material)],
        background=PlaneObject((2.0, 2.0), Pose(np.eye(3), (0.0, 0.0, 1.3)), material),
    )


def uncertainty_scenes() -> dict[str, Scene]:
    """The scenes the uncertainty model is checked against Monte Carlo on (test and bench):
    a matte tilted plane, and a matte 24 mm sphere before a plane; at 1 m the sphere fills
    most of a 48 px cropped camera's (21 mm) field, so its shading and slope spread sigma
    over the pixels."""
    matte = Material(albedo=0.8, specular=0.0)
    tilted = Pose.from_euler("xyz", [20.0, -25.0, 0.0], t=(0, 0, 1.0))
    return {
        "plane": Scene(objects=[], background=PlaneObject((1.0, 1.0), tilted, matte)),
        "sphere": Scene(
            objects=[SphereObject(0.012, (0.0, 0.0, 1.0), matte)],
            background=PlaneObject((2.0, 2.0), Pose(np.eye(3), (0.0, 0.0, 1.3)), matte),
        ),
    }


def tilted_plane() -> PlaneObject:
    """A 1 m x 1 m plane through (0, 0, 1) m, tilted 20 deg about x and -25 deg about y."""
    return PlaneObject((1.0, 1.0), Pose.from_euler("xyz", [20.0, -25.0, 0.0], t=(0, 0, 1.0)))


def plane_depth(intrinsics: Intrinsics, plane: PlaneObject) -> np.ndarray:
    """(H, W) analytic depth of the pixel-centre rays on ``plane`` (camera = world frame)."""
    normal, point = plane.pose.R[:, 2], plane.pose.t
    rays = intrinsics.unproject(intrinsics.pixel_grid().reshape(-1, 2))
    distance = (normal @ point) / (rays @ normal)
    return (distance * rays[:, 2]).reshape(intrinsics.height, intrinsics.width)


def fit_sphere_lsq(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Geometric least-squares sphere (centre (3,), radius) of (N, 3) points, started from
    the algebraic fit (which alone is biased by structured errors such as a staircase)."""
    a = np.c_[2 * points, np.ones(len(points))]
    b = (points**2).sum(axis=1)
    x = np.linalg.lstsq(a, b, rcond=None)[0]
    start = np.r_[x[:3], np.sqrt(x[3] + x[:3] @ x[:3])]
    result = least_squares(
        lambda p: np.linalg.norm(points - p[:3], axis=1) - p[3], start, method="lm"
    )
    return result.x[:3], float(result.x[3])
