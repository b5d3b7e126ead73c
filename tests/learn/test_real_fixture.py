"""The committed real capture (tests/fixtures/real/slmaster_eye: a crop of SLMaster's
MIT-licensed 12-step + complementary-Gray-code capture of a plaster relief, its calibration
adjusted for the crop): small and licensed, ``virtus import`` reads it, its multi-step decode
is sane, ``virtus learn eval --captures`` runs on it offline, and the sim-to-real bench
prepares it.

Reference values were measured on the full-size source frames (1280 x 1024,
``benchmarks/bench_sim2real.py`` docstring): depth 0.694-0.775 m (1st-99th percentile),
median 0.727 m; the binned crop's depth agrees with the full-size frames' 2 x 2 block means
to 0.04 mm (median absolute difference over 53 k pixels)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from tests.data.test_dataset import run_cli
from tests.learn.conftest import bench_sim2real

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "real" / "slmaster_eye"
#: The fixture's budget (the issue's "small derived fixture"), bytes.
MAX_BYTES = 1_500_000
#: Frames of the sequence: 12 phase steps, 5 Gray bits, the complementary frame.
N_FRAMES = 18


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    """The fixture imported as a capture (what ``virtus import`` writes)."""
    from virtus.pipeline.capture import import_images

    out = tmp_path_factory.mktemp("slmaster") / "capture"
    import_images(FIXTURE / "images", FIXTURE / "sequence.yaml", FIXTURE / "rig.json", out)
    return out


def test_the_fixture_is_small_licensed_and_traceable() -> None:
    files = [f for f in FIXTURE.rglob("*") if f.is_file()]
    assert sum(f.stat().st_size for f in files) <= MAX_BYTES
    licence = (FIXTURE / "LICENSE").read_text()
    assert licence.startswith("MIT License") and "Copyright (c) 2024 Liu Yunhuang" in licence
    source = json.loads((FIXTURE / "SOURCE.json").read_text())
    bench = bench_sim2real()
    assert source["commit"] == bench.SLMASTER_COMMIT and len(source["sha256"]) == N_FRAMES
    readme = (FIXTURE / "README.md").read_text()
    assert bench.SLMASTER_COMMIT in readme and "MIT" in readme
    from PIL import Image

    images = sorted((FIXTURE / "images").glob("*.png"))
    assert [p.name for p in images] == [f"{i:02d}.png" for i in range(N_FRAMES)]
    for path in images:
        frame = np.asarray(Image.open(path))
        assert frame.shape == (256, 256) and frame.dtype == np.uint8


def test_the_rig_is_the_source_calibration_cropped_and_binned() -> None:
    """rig.json = caliInfo.yml (through calibration.yaml) with the camera's principal point
    moved by the crop and the camera halved by the 2 x 2 binning; the rest unchanged."""
    from virtus.calib.io import load_calibration_report
    from virtus.geometry.devices import Rig

    bench = bench_sim2real()
    full, _ = load_calibration_report(FIXTURE / "calibration.yaml")
    rig = Rig.load_json(FIXTURE / "rig.json")
    x0, y0, _, _ = bench.FIXTURE_CROP
    k, c = full.camera.intrinsics, rig.camera.intrinsics
    assert (c.width, c.height) == (256, 256)
    np.testing.assert_allclose([c.fx, c.fy], [k.fx / 2, k.fy / 2], rtol=1e-12)
    np.testing.assert_allclose(
        [c.cx, c.cy], [(k.cx - x0 + 0.5) / 2 - 0.5, (k.cy - y0 + 0.5) / 2 - 0.5], rtol=1e-12
    )
    assert c.dist == k.dist and rig.projector == full.projector
    np.testing.assert_allclose(rig.proj2cam.t, full.proj2cam.t, atol=1e-15)
    # the projector sits beside the camera: vertical fringes carry depth
    np.testing.assert_allclose(rig.proj2cam.t, [0.10638, 0.00420, 0.02535], atol=1e-5)


def test_virtus_import_reads_the_fixture(tmp_path, capsys) -> None:
    out = tmp_path / "capture"
    code, stdout, err = run_cli(
        [
            "import", FIXTURE / "images", "--sequence", FIXTURE / "sequence.yaml",
            "--calibration", FIXTURE / "rig.json", "--out", out, "--json",
        ],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    data = json.loads(stdout)
    assert (data["frames"], data["width"], data["height"]) == (N_FRAMES, 256, 256)
    assert data["bit_depth"] == 8 and data["sequence_frames"] == N_FRAMES
    assert data["baseline_mm"] == pytest.approx(109.4, abs=0.1)
    assert (out / "capture.json").is_file()


def test_the_multi_step_decode_is_sane(imported) -> None:
    from virtus.capture.capture import Capture
    from virtus.reconstruct import reconstruct

    capture = Capture.load(imported)
    decoded = capture.decode()
    mask = decoded.mask_v
    # the relief fills most of the crop; the margin is unlit background (measured: 0.82)
    assert 0.70 < mask.mean() < 0.90
    # the unwrapping residual check flags almost nothing (measured: 2e-5 of valid pixels)
    assert decoded.flagged_v[mask].mean() < 1e-3
    # absolute phase grows along the rows (u_p increases with the camera column, the
    # projector being to the camera's right), ~0.30 rad per binned px (60 px periods)
    step = np.diff(decoded.phase_v, axis=1)
    step = step[np.isfinite(step)]
    assert (step > 0).mean() > 0.98
    assert 0.25 < np.median(step) < 0.36
    # the full-size frames put the relief at 0.694-0.775 m, median 0.727 m
    points = reconstruct(capture.rig, decoded.proj_uv, decoded.mask_v, use="u").points
    depth = points[..., 2][np.isfinite(points[..., 2])]
    assert depth.size > 0.6 * mask.size
    assert 0.72 < np.median(depth) < 0.735
    low, high = np.percentile(depth, (1, 99))
    assert 0.68 < low and high < 0.79


@pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="needs torch")
def test_learn_eval_runs_on_the_fixture(phase_run, imported, capsys) -> None:
    """A tiny phase head (one epoch on a tiny rendered store) on the real capture: the
    metrics exist and are finite. No accuracy is claimed for such a model."""
    code, out, err = run_cli(
        ["learn", "eval", phase_run, "--captures", imported, "--json", "--no-report"], capsys
    )
    assert code == 0, err
    summary = json.loads(out)
    assert summary["samples"] == 1 and summary["reference"].startswith("multi-step")
    assert summary["valid_share"] > 0.7
    assert 0 < summary["phase_rmse_rad"] <= np.pi
    assert np.isfinite(summary["object_mae_mm"]) and summary["object_mae_mm"] > 0
    on_disk = json.loads((phase_run / "evaluations" / "captures.json").read_text())
    assert on_disk["captures"] == [str(imported.resolve())]
    assert on_disk["phase_rmse_rad"] == summary["phase_rmse_rad"]


def test_the_sim2real_bench_prepares_the_fixture(tmp_path) -> None:
    """``prepare-fixture`` writes what ``run`` reads; ``run``'s stores then use the
    fixture's sequence and vertical fringes, its rig, and scenes at the relief's standoff."""
    bench = bench_sim2real()
    real = tmp_path / "real"
    report = bench.prepare_fixture(FIXTURE, real)
    assert report["bench"] == "slmaster-eye" and report["reference_valid_fraction"] > 0.7
    assert (real / "capture" / "capture.json").is_file() and (real / "rig.json").is_file()
    chosen = bench.bench_of(real)
    assert chosen["name"] == "slmaster-eye" and chosen["direction"] == "v"
    config = bench.dataset_config(real, "ideal", 4)
    assert config.num_samples == 4
    assert config.fringes.directions == ("v",)
    assert [Path(s).resolve() for s in config.fringes.sequences] == [
        (FIXTURE / "sequence.yaml").resolve()
    ]
    assert bench.bench_of(tmp_path)["name"] == "lightcrafter-lab"  # nothing recorded
