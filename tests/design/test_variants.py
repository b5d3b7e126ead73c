"""Design sweep keys (virtus.design.variants): parsing, the scanner each variant builds, and
the refusal of rigs whose devices do not overlap."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tolerances import FLOAT64_EXACT
from virtus.design.variants import (
    KEYS,
    MAX_VARIANTS,
    coarse_camera,
    overlap_fraction,
    parse_vary,
    variants,
    with_coarse_camera,
)
from virtus.errors import InputError
from virtus.geometry.devices import default_rig
from virtus.scanner import Scanner
from virtus.sensor import SENSOR_PRESETS


def test_parse_vary_reads_every_key_and_keeps_the_order():
    vary = parse_vary(["steps=3,4,18", "period_px=18,36", "sensor=imx174,webcam,imx174"])
    assert vary == {"steps": [3, 4, 18], "period_px": [18.0, 36.0], "sensor": ["imx174", "webcam"]}
    chosen = variants(vary)
    assert len(chosen) == 12
    assert chosen[1].values == (("steps", 3), ("period_px", 18.0), ("sensor", "webcam"))
    assert chosen[1].name == "steps=3,period_px=18.0,sensor=webcam"
    assert len({v.file for v in chosen}) == 12


@pytest.mark.parametrize(
    ("items", "message"),
    [
        (["focal=1,2"], "--vary key: expected one of baseline_mm"),
        (["steps"], "--vary: expected KEY=V1,V2"),
        (["steps="], "--vary: expected KEY=V1,V2"),
        (["steps=2,3"], "--vary steps: expected an integer in [3, 64]"),
        (["steps=4.5"], "--vary steps: expected an integer"),
        (["baseline_mm=0"], "--vary baseline_mm: expected a number in (0, 5000]"),
        (["baseline_mm=nan"], "--vary baseline_mm"),
        (["bit_depth=14"], "--vary bit_depth: expected values among (8, 10, 12, 16)"),
        (["sensor=cmos"], "--vary sensor: expected one of ideal"),
        (["coding=phase"], "--vary coding: expected one of gray, heterodyne"),
        (["steps=3", "steps=4"], "--vary key: expected each key once"),
        ([], "--vary: expected at least one"),
        ([f"period_px={','.join(str(3 + i) for i in range(65))}"], "at most 64 values"),
    ],
)
def test_parse_vary_refuses_bad_input_naming_it(items, message):
    with pytest.raises(InputError) as error:
        parse_vary(items)
    assert message in str(error.value)


def test_parse_vary_bounds_the_product():
    values = ",".join(str(3 + i) for i in range(40))
    with pytest.raises(InputError, match=f"at most {MAX_VARIANTS} variants"):
        parse_vary([f"steps={values}", f"period_px={values}"])


def test_every_key_builds_its_change():
    base = Scanner()
    for item, check in [
        ("baseline_mm=250", lambda s, d: np.linalg.norm(s.rig.proj2cam.t) == pytest.approx(0.25)),
        ("working_distance_m=0.5", lambda s, d: d == 0.5),
        ("period_px=36", lambda s, d: min(s.sequence.periods("v")) == 36.0),
        ("steps=4", lambda s, d: s.sequence.plan("h").sets[0].coding.steps == 4),
        ("coding=heterodyne", lambda s, d: s.sequence.plan("v").method == "heterodyne"),
        ("sensor=webcam", lambda s, d: s.sensor == SENSOR_PRESETS["webcam"]),
        ("exposure=0.5", lambda s, d: s.sensor.auto_target == 0.5),
        ("bit_depth=12", lambda s, d: s.sensor.bit_depth == 12),
        ("projector=lightcrafter", lambda s, d: s.projector.name == "lightcrafter"),
        ("blur_px=2", lambda s, d: s.projector.psf_sigma_px == 2.0),
    ]:
        (variant,) = variants(parse_vary([item]))
        scanner, distance = variant.build(base)
        assert check(scanner, distance), item
    assert set(KEYS) >= {"baseline_mm", "toe_in_deg", "period_px", "blur_px"}


def test_toe_in_is_the_angle_between_the_optical_axes():
    for degrees in (0.0, 5.0, 12.0):
        (variant,) = variants(parse_vary([f"toe_in_deg={degrees}"]))
        scanner, _ = variant.build(Scanner())
        axis = scanner.rig.proj2cam.R[:, 2]
        angle = np.degrees(np.arccos(np.clip(axis[2], -1, 1)))
        assert angle == pytest.approx(degrees, abs=1e-9)
        # the projector keeps its centre
        np.testing.assert_allclose(scanner.rig.proj2cam.t, default_rig().proj2cam.t,
                                   atol=FLOAT64_EXACT)  # fmt: skip


def test_the_base_rig_aims_at_the_working_distance_as_the_paper_rig_does():
    (variant,) = variants(parse_vary(["working_distance_m=1.0"]))
    scanner, _ = variant.build(Scanner())
    np.testing.assert_allclose(scanner.rig.proj2cam.R, default_rig().proj2cam.R, atol=1e-12)


def test_overlap_fraction_sees_devices_that_do_not_overlap():
    rig = default_rig()
    assert overlap_fraction(rig, 1.0) == 1.0  # the projector covers the camera at 1 m
    far_apart = variants(parse_vary(["baseline_mm=1000", "toe_in_deg=0"]))[0]
    scanner, distance = far_apart.build(Scanner())
    assert overlap_fraction(scanner.rig, distance) == 0.0
    crossed = variants(parse_vary(["toe_in_deg=40"]))[0].build(Scanner())[0]
    assert overlap_fraction(crossed.rig, 1.0) == 0.0  # axes cross at 0.19 m


def test_coarse_camera_keeps_the_field_of_view():
    k = default_rig().camera.intrinsics
    coarse = coarse_camera(k, 64)
    assert (coarse.width, coarse.height) == (64, 64)
    corners = np.array([[-0.5, -0.5], [k.width - 0.5, k.height - 0.5]])
    small = np.array([[-0.5, -0.5], [63.5, 63.5]])
    np.testing.assert_allclose(coarse.unproject(small), k.unproject(corners), atol=1e-12)
    scanner = with_coarse_camera(Scanner(), 32)
    assert scanner.render.spp == 1 and scanner.rig.camera.intrinsics.width == 32
