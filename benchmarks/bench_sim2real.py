"""Sim-to-real: does training on a realistic virtual sensor help a single-shot phase network
on a real bench? The phase head (:mod:`virtus.learn`) trained on virtus data of one real
lab's rig, once with the sensor and projector fitted to that lab's capture and once with
ideal ones, evaluated on the lab's real capture against its own multi-step phase.

The real bench: github.com/kimthyung/3D_Reconstruction_with_Fringe_pattern (commit
561120b, ``3D_reconstruction/data00/p00``: 52 BMPs, 1936 x 1464, 8 bit, a 7 x 21
white-on-black circle board at ~320 mm, a DLP LightCrafter 4500; the lab's OpenCV
calibration). It has **no licence**: nothing of it is committed; ``prepare`` writes a
compact derived copy into a git-ignored folder for one's own runs. Its projector is 126 mm
below the camera and 6 mm beside it, so depth comes from the **horizontal** fringes
(``direction: h``; ``examples/datasets/sim2real/lightcrafter_lab_h.yaml``): at 320 mm,
``v_p`` moves 0.85 projector px per mm of depth at the image centre, ``u_p`` 0.05 (and
not at all on one column near the left edge).

Two steps::

    # 1. here (CPU, ~10 s): the compact capture (26 frames binned 4 x 4: 484 x 366, 1.5 MB
    #    of PNG), its rig, and the light fitted to it (virtus twin --fit's fit)
    PYTHONPATH=src python benchmarks/bench_sim2real.py prepare \\
        /work/.mirror/kimthyung+3D_Reconstruction_with_Fringe_pattern/repo --out .gpu-work/real

    # 2. on one GPU (or a tiny CPU check with the defaults: ~3 min on 2 cores): stores,
    #    training, evaluation
    PYTHONPATH=src python benchmarks/bench_sim2real.py run .gpu-work/real --out .gpu-work/s2r \\
        --num 640 --steps 1500 --base-channels 32 --batch-size 8 --workers 12 \\
        --loader-workers 8 --json sim2real.json

``run`` (a) generates one store per variant on the lab's rig and sequence
(``examples/datasets/sim2real/lab.yaml``: one to two matte objects at 0.25-0.33 m before a
tilted plane at 0.30-0.42 m, the board's standoff; the same scenes in every store):
``realistic`` (the sensor and projector ``prepare`` fitted to the capture -- exposure, gain
and noise, blur, vignetting, fall-off; the imx174 + lightcrafter presets where the fit
failed) and ``ideal`` (the ideal presets: noise-free, auto exposure); optionally
``ideal-exposed`` (noise-free at the fitted exposure: brightness apart from noise and
optics; on this capture the ideal and fitted inputs' levels differ little, mean 0.12
against 0.09 of full scale, so it is left out by default); (b) trains the phase head
(``direction: h``) on each with the same seed and the same number of optimiser steps; (c)
evaluates each on its own store's test split and on the real capture
(:func:`virtus.learn.evaluate_captures`: phase RMSE and depth MAE against the capture's
18-step + Gray-code reconstruction); (d) prints the table. Every step resumes: rerun the
same command after a kill.

The real capture is a flat board (white circles on black): "depth MAE" there is against the
capture's own multi-step depth over its valid pixels, not against a ground truth.

A second, **licensed** real bench is committed (``tests/fixtures/real/slmaster_eye``, its
README): github.com/Practice3DVision/SLMaster (commit 592a368, MIT at that commit),
``data/monocularCamera``: a plaster relief of an eye at 0.69-0.78 m, a DLP4710 106 mm to the
camera's right (so **vertical** fringes, ``direction: v``), 12 phase steps of a 60 px
period + 5 Gray bits + the complementary frame, the lab's OpenCV calibration; the fixture
keeps the 18 frames cropped to the relief and binned 2 x 2 (256 x 256 px, 0.56 MB) with the
calibration adjusted for the crop. ``fixture SLMASTER_GIT_DIR`` derives it (once; the same
bytes each time), ``prepare-fixture`` turns it into what ``run`` reads (no light fit: the
capture has no white or black frame, so ``realistic`` uses the imx174 + lightcrafter
presets), and ``run`` then uses the fixture's sequence, vertical fringes and scenes at its
standoff (:data:`BENCHES`)::

    PYTHONPATH=src python benchmarks/bench_sim2real.py prepare-fixture --out .gpu-work/real-slm
    PYTHONPATH=src python benchmarks/bench_sim2real.py run .gpu-work/real-slm \\
        --out .gpu-work/s2r-slm --num 640 --steps 1500 --base-channels 32 --batch-size 8 \\
        --workers 12 --loader-workers 8 --json sim2real-slmaster.json

Not a test: numbers depend on the machine (quote them with it and the sizes).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "examples" / "datasets" / "sim2real"
#: The dataset configuration template (rig, sensor and projector are filled in by ``run``).
TEMPLATE = HERE / "lab.yaml"
#: The horizontal half of the lab's sequence: the frames the compact capture keeps.
SEQUENCE = HERE / "lightcrafter_lab_h.yaml"
#: The real frames of SEQUENCE, in its order: phase 0-17, Gray 18-22, black 23-24, white 51.
REAL_FRAMES = (*range(25), 51)
#: The lab's camera (px).
FULL_SIZE = (1936, 1464)
#: Variants: (sensor, projector) choices, resolved by :func:`_devices`.
VARIANTS = ("realistic", "ideal", "ideal-exposed")
#: The real benches ``run`` knows, by the ``bench`` that ``prepare``/``prepare-fixture``
#: record in ``SOURCE.json`` (none recorded: the LightCrafter lab): the fringe direction
#: that carries depth, the depth-loss unit, what the reference is, and what ``run`` changes
#: in :data:`TEMPLATE` (``None``: resolved by :func:`_bench_dataset`).
BENCHES = {
    "lightcrafter-lab": {
        "direction": "h",
        "depth_range_m": 0.05,  # depth L1 in units of 5 cm (the scenes' depth span)
        "reference": "its 18-step + Gray-code phase",
        "dataset": {},
    },
    "slmaster-eye": {
        "direction": "v",  # the projector is 106 mm beside the camera
        "depth_range_m": 0.1,  # the relief spans 0.69-0.78 m
        "reference": "its 12-step + complementary Gray-code phase",
        # SLMaster's sequence, scenes at the relief's standoff: one or two objects at
        # 0.66-0.76 m before a tilted plane at 0.74-0.86 m; bright matte (plaster).
        "dataset": {
            "fringes": None,
            "objects": {
                "count": [1, 2],
                "distance_m": [0.66, 0.76],
                "field": 0.6,
                "sources": [
                    {"type": "freeform", "size_m": [0.06, 0.18], "instances": 40,
                     "subdivisions": 4, "weight": 2},
                    {"type": "box", "size_m": [0.04, 0.14], "instances": 20},
                    {"type": "sphere", "radius_m": [0.02, 0.07], "instances": 20},
                ],
            },
            "materials": {"albedo": [0.5, 0.95], "roughness": [0.95, 0.95],
                          "specular": [0.15, 0.15]},
            "planes": {"count": [1, 1], "distance_m": [0.74, 0.86], "tilt_deg": 25,
                       "size_m": 1.5},
        },
    },
}  # fmt: skip


# -- prepare (runs here, on the real capture) ------------------------------------------------


def _bin(frame: np.ndarray, factor: int) -> np.ndarray:
    """Mean of ``factor x factor`` blocks (pixel edges kept: ``Intrinsics.scaled(1/factor)``),
    rounded back to uint8."""
    h, w = frame.shape
    blocks = frame.reshape(h // factor, factor, w // factor, factor).astype(np.float64)
    return np.clip(np.rint(blocks.mean(axis=(1, 3))), 0, 255).astype(np.uint8)


def _circles(capture, factor: int) -> np.ndarray:
    """The board's white circles (``bench_twin_real.white_circles``), eroded off their
    blurred edges: the one-albedo pixels the light is fitted on."""
    from scipy import ndimage

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_twin_real import white_circles

    circles, _ = white_circles(capture, factor)
    return ndimage.binary_erosion(circles, iterations=max(1, 5 // factor))


def _write_yaml(path: Path, data: dict, what: str) -> None:
    import yaml

    path.write_text(f"# {what}\n" + yaml.safe_dump(data, sort_keys=False))


def _fit(capture, rig, factor: int, fit_dir: Path) -> str | None:
    """Fit the light to ``capture`` (:func:`virtus.twin.photometric.fit_photometry`, what
    ``virtus twin --fit`` runs) on the board's white circles; write ``fit_dir/sensor.yaml``,
    ``projector.yaml``, ``ideal_exposed.yaml`` and ``photometric.json``. The error's text
    where it fails (``run`` then uses the presets)."""
    import virtus.twin.photometric as photometric
    from virtus.sensor.camera import Sensor

    fit_dir.mkdir(exist_ok=True)
    # The normals' smoothing is in camera px: the same 2 full-size px on the binned image,
    # or the binned circles (~12 px) leave no pixel with full support.
    smooth = photometric.NORMAL_SMOOTH_PX
    photometric.NORMAL_SMOOTH_PX = smooth / factor
    try:
        fit = photometric.fit_photometry(
            [capture], rig, prior_sensor=Sensor(bit_depth=8), regions=[_circles(capture, factor)]
        )
    except Exception as error:  # noqa: BLE001 - any failure: run falls back to presets
        return f"{type(error).__name__}: {error}"
    finally:
        photometric.NORMAL_SMOOTH_PX = smooth
    _write_yaml(fit_dir / "sensor.yaml", fit.sensor.to_dict(), "camera fitted to the capture")
    _write_yaml(
        fit_dir / "projector.yaml", fit.projector.to_dict(), "projector fitted to the capture"
    )
    exposed = {"name": "ideal-exposed", "bit_depth": 8, "exposure": fit.sensor.exposure}
    _write_yaml(fit_dir / "ideal_exposed.yaml", exposed, "noise-free, at the fitted exposure")
    (fit_dir / "photometric.json").write_text(json.dumps(fit.to_dict(), indent=1, default=float))
    return None


def prepare(source: Path, out: Path, factor: int) -> dict:
    """The compact capture ``out/capture`` (REAL_FRAMES binned by ``factor``), its rig
    ``out/rig.json`` and the fitted light ``out/fit/`` (module docstring). Idempotent:
    what exists is kept."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_twin_real import COMMIT, stage
    from bench_twin_real import SEQUENCE as FULL_SEQUENCE
    from PIL import Image

    from virtus.calib.io import load_calibration_report
    from virtus.capture.capture import Capture
    from virtus.geometry.devices import Camera, Rig
    from virtus.io.images import read_image
    from virtus.patterns import load_sequence_file
    from virtus.pipeline.capture import import_images

    if FULL_SIZE[0] % factor or FULL_SIZE[1] % factor:
        raise SystemExit(f"--bin {factor}: must divide {FULL_SIZE[0]} and {FULL_SIZE[1]}")
    out.mkdir(parents=True, exist_ok=True)
    capture_dir, rig_file, fit_dir = out / "capture", out / "rig.json", out / "fit"
    report: dict = {
        "source": f"kimthyung/3D_Reconstruction_with_Fringe_pattern@{COMMIT[:7]} (no licence: "
        "not for redistribution)",
        "frames": list(REAL_FRAMES),
        "bin": factor,
    }
    done = (capture_dir / "capture.json").is_file() and (fit_dir / "sensor.yaml").is_file()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        images, calibration = stage(source, work) if not done else (None, None)
        if not (capture_dir / "capture.json").is_file():
            binned = work / "binned"
            binned.mkdir()
            for i, index in enumerate(REAL_FRAMES):
                frame = read_image(images / f"{index:02d}.bmp")
                Image.fromarray(_bin(frame, factor)).save(binned / f"{i:02d}.png")
            full, _ = load_sequence_file(FULL_SEQUENCE)
            rig, _ = load_calibration_report(
                calibration, units="mm", camera_size=FULL_SIZE,
                projector_size=(full.width, full.height),
            )  # fmt: skip
            rig = Rig(Camera(rig.camera.intrinsics.scaled(1 / factor)), rig.projector, rig.proj2cam)
            rig.save_json(rig_file)
            import_images(binned, SEQUENCE, rig_file, capture_dir)
        if not (fit_dir / "sensor.yaml").is_file():
            # The fit triangulates with both directions: all 52 frames, binned alike (kept
            # only in this temporary folder).
            every = work / "every"
            every.mkdir()
            for index in range(52):
                frame = read_image(images / f"{index:02d}.bmp")
                Image.fromarray(_bin(frame, factor)).save(every / f"{index:02d}.png")
            both = import_images(every, FULL_SEQUENCE, rig_file, work / "both").capture
            report["fit_error"] = _fit(both, Rig.load_json(rig_file), factor, fit_dir)
    capture = Capture.load(capture_dir)
    report["camera_size"] = [capture.frames.shape[2], capture.frames.shape[1]]
    if (fit_dir / "photometric.json").is_file():
        fitted = json.loads((fit_dir / "photometric.json").read_text())
        report["fit"] = {
            "sensor": fitted["sensor"],
            "projector": fitted["projector"],
            "ambient": fitted["ambient"],
            "notes": fitted.get("notes", []),
        }
    decoded = capture.decode()
    report["reference_valid_fraction"] = float(decoded.mask_h.mean())
    report["bytes"] = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    (out / "SOURCE.json").write_text(json.dumps(report, indent=1, default=float))
    return report


# -- the licensed fixture (tests/fixtures/real/slmaster_eye; runs here, once) ----------------

#: The public capture the committed fixture derives from: ``data/monocularCamera`` of
#: github.com/Practice3DVision/SLMaster at this commit, where the repository's LICENSE is
#: MIT (it became AGPL-3.0 on 2024-04-08, commit cc64865; the data are unchanged since).
SLMASTER_REPO = "Practice3DVision/SLMaster"
SLMASTER_COMMIT = "592a368b1f8136a07ea1281e8bb2948a2435f45a"
SLMASTER_DATA = "data/monocularCamera"
#: The committed fixture.
FIXTURE = ROOT / "tests" / "fixtures" / "real" / "slmaster_eye"
#: Its crop of the 1280 x 1024 frames, full-size px ``(x0, y0, width, height)`` (the plaster
#: relief and a margin of background), binned ``FIXTURE_BIN x FIXTURE_BIN``: 256 x 256 px.
FIXTURE_CROP = (428, 346, 512, 512)
FIXTURE_BIN = 2
#: The capture's sequence (SLMaster's ``SinusCompleGrayCodePattern`` as its monocular
#: camera's configuration sets it: 12 steps, 32 periods over the DLP4710's 1920 columns).
FIXTURE_SEQUENCE = """\
# SLMaster's monocular capture (github.com/Practice3DVision/SLMaster@592a368,
# data/monocularCamera/L/0-17.bmp), as its pattern generator writes the frames
# (src/algorithm/cpuStructuredLight/sinus_comple_graycode_pattern.cpp, generate()) with the
# configuration of gui/qml/res/config/monocularCameraConfig.json: vertical fringes, 12 phase
# steps, 32 periods over the 1920 columns (60 px each), 18 frames. Height 1080: the DLP4710's
# rows (the configuration says 1024; vertical fringes do not depend on rows).
#   frame i = 0..11: 127.5 + 127.5 cos(2 pi (x mod 60) / 60 - pi + 2 pi i / 12) for column x
#     -> first_step: 0, offset -pi (offset_steps: -6), sign +1, period 60
#   frames 12..16: Gray code of floor(x / 60), most significant bit first (blocks of
#     1920 / 2^(b+1) px, reflected) -> bits: 5, msb_first, align: edge
#   frame 17: the complementary frame, the last bit of the 6-bit Gray code of floor(x / 30)
#     -> complement: true
# No white or black frame: each code bit is thresholded at the phase frames' mean.
format: virtus.pattern_sequence
version: 2
width: 1920
height: 1080
blocks:
  - {kind: phase, direction: v, period: 60, steps: 12, first_step: 0, offset_steps: -6}
  - {kind: gray, direction: v, period: 60, bits: 5, bit_order: msb_first, align: edge,
     complement: true}
"""
#: Which node of SLMaster's ``caliInfo.yml`` is which (its ``reverseCamera`` builds the
#: projector's matrix as ``M4 [Rlp | Tlp]``: camera to projector, millimetres).
FIXTURE_MAPPING = """\
# SLMaster's calibration (caliInfo.yml, OpenCV FileStorage, full-size 1280 x 1024 camera):
# M1 D1 camera, M4 D4 projector (DLP4710, 1920 x 1080), Rlp Tlp camera -> projector in mm
# (its depth recovery projects camera-frame points with M4 [Rlp | Tlp]).
file: caliInfo.yml
keys:
  camera_K: M1
  camera_dist: D1
  projector_K: M4
  projector_dist: D4
  R: Rlp
  T: Tlp
units: mm
convention: X_proj = R X_cam + T
camera_size: [1280, 1024]
projector_size: [1920, 1080]
"""


def _git_show(source: Path, path: str) -> bytes:
    """``path`` at :data:`SLMASTER_COMMIT` of the git directory (bare or a clone) ``source``."""
    import subprocess

    done = subprocess.run(
        ["git", "-C", str(source), "show", f"{SLMASTER_COMMIT}:{path}"],
        capture_output=True,
        check=False,
    )
    if done.returncode:
        message = done.stderr.decode(errors="replace").strip()
        raise SystemExit(f"{source}: no {path} at {SLMASTER_COMMIT[:7]} ({message})")
    return done.stdout


def cropped_rig(rig, crop: tuple[int, int, int, int], factor: int):
    """``rig`` with its camera cropped to ``crop`` = ``(x0, y0, width, height)`` full-size px
    (the principal point moves by ``-(x0, y0)``) and then binned ``factor x factor``
    (:meth:`~virtus.geometry.optics.Intrinsics.scaled`: pixel edges kept). The focal lengths,
    the distortion, the projector and ``proj2cam`` are unchanged."""
    from virtus.geometry.devices import Camera, Rig
    from virtus.geometry.optics import Intrinsics

    x0, y0, width, height = crop
    k = rig.camera.intrinsics
    window = Intrinsics(k.fx, k.fy, k.cx - x0, k.cy - y0, width, height, k.dist)
    return Rig(Camera(window.scaled(1 / factor)), rig.projector, rig.proj2cam)


def make_fixture(source: Path, out: Path) -> dict:
    """Derive the committed fixture from SLMaster's capture (module docstring): the 18
    frames cropped to :data:`FIXTURE_CROP` and binned by :data:`FIXTURE_BIN` as PNG, the
    sequence, the original calibration with its mapping, the rig of the cropped camera, the
    licence and ``SOURCE.json`` (provenance and the source frames' SHA-256). Deterministic:
    the same source gives the same bytes. ``README.md`` is written by hand."""
    import hashlib
    import io

    from PIL import Image

    from virtus.calib.io import load_calibration_report

    licence = _git_show(source, "LICENSE")
    if not licence.startswith(b"MIT License"):
        raise SystemExit(f"{source}: LICENSE at {SLMASTER_COMMIT[:7]} is not MIT")
    x0, y0, width, height = FIXTURE_CROP
    (out / "images").mkdir(parents=True, exist_ok=True)
    digests = {}
    for index in range(18):
        path = f"{SLMASTER_DATA}/L/{index}.bmp"
        data = _git_show(source, path)
        digests[path] = hashlib.sha256(data).hexdigest()
        frame = np.asarray(Image.open(io.BytesIO(data)))
        if frame.shape != (1024, 1280) or frame.dtype != np.uint8:
            raise SystemExit(f"{path}: expected a 1280 x 1024 8-bit frame, got {frame.shape}")
        binned = _bin(frame[y0 : y0 + height, x0 : x0 + width], FIXTURE_BIN)
        Image.fromarray(binned).save(out / "images" / f"{index:02d}.png", optimize=True)
    (out / "LICENSE").write_bytes(licence)
    (out / "caliInfo.yml").write_bytes(_git_show(source, f"{SLMASTER_DATA}/caliInfo.yml"))
    (out / "calibration.yaml").write_text(FIXTURE_MAPPING)
    (out / "sequence.yaml").write_text(FIXTURE_SEQUENCE)
    full, _ = load_calibration_report(out / "calibration.yaml")
    cropped_rig(full, FIXTURE_CROP, FIXTURE_BIN).save_json(out / "rig.json")
    report = {
        "source": f"https://github.com/{SLMASTER_REPO}",
        "commit": SLMASTER_COMMIT,
        "path": SLMASTER_DATA,
        "licence": "MIT (LICENSE at that commit; AGPL-3.0 from cc64865, 2024-04-08)",
        "crop_xywh_px": list(FIXTURE_CROP),
        "bin": FIXTURE_BIN,
        "sha256": digests,
    }
    (out / "SOURCE.json").write_text(json.dumps(report, indent=1) + "\n")
    report["bytes"] = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    return report


def prepare_fixture(fixture: Path, out: Path) -> dict:
    """What ``run`` reads, from the committed fixture: ``out/capture`` (``virtus import`` of
    its frames with its sequence and rig), ``out/rig.json`` and ``out/SOURCE.json`` naming
    the bench (``slmaster-eye``: vertical fringes). No light is fitted (the capture has no
    white or black frame, which the fit needs): ``realistic`` uses the presets. Idempotent."""
    import shutil

    from virtus.capture.capture import Capture
    from virtus.pipeline.capture import import_images

    out.mkdir(parents=True, exist_ok=True)
    if not (out / "capture" / "capture.json").is_file():
        import_images(
            fixture / "images", fixture / "sequence.yaml", fixture / "rig.json", out / "capture"
        )
    shutil.copyfile(fixture / "rig.json", out / "rig.json")
    decoded = Capture.load(out / "capture").decode()
    report = {
        "bench": "slmaster-eye",
        "source": json.loads((fixture / "SOURCE.json").read_text()),
        "fixture": str(fixture),
        "fit_error": "no white or black frames: the presets stand for the fitted devices",
        "reference_valid_fraction": float(decoded.mask_v.mean()),
    }
    (out / "SOURCE.json").write_text(json.dumps(report, indent=1, default=float))
    return report


# -- run (GPU or a tiny CPU check) -----------------------------------------------------------


def _devices(real: Path, variant: str) -> tuple[list[str], list[str]]:
    """(sensor, projector) choices of a variant; the fitted files where ``prepare`` wrote
    them, else imx174 + lightcrafter (and the ideal sensor for ``ideal-exposed``)."""
    fit = real.resolve() / "fit"
    fitted = (fit / "sensor.yaml").is_file()
    if variant == "ideal":
        return ["ideal"], ["ideal"]
    if variant == "ideal-exposed":
        return [str(fit / "ideal_exposed.yaml") if fitted else "ideal"], ["ideal"]
    if fitted:
        return [str(fit / "sensor.yaml")], [str(fit / "projector.yaml")]
    return ["imx174"], ["lightcrafter"]


def bench_of(real: Path) -> dict:
    """The :data:`BENCHES` entry of a prepared folder (its ``SOURCE.json``'s ``bench``)."""
    source = real / "SOURCE.json"
    name = json.loads(source.read_text()).get("bench") if source.is_file() else None
    name = name or "lightcrafter-lab"
    if name not in BENCHES:
        raise SystemExit(f"{source}: unknown bench {name!r} (known: {sorted(BENCHES)})")
    return {"name": name, **BENCHES[name]}


def _bench_dataset(real: Path, bench: dict) -> dict:
    """The bench's changes to :data:`TEMPLATE`; the fixture's own sequence for
    ``slmaster-eye`` (the one its capture was taken with)."""
    changes = dict(bench["dataset"])
    if "fringes" in changes:
        source = json.loads((real / "SOURCE.json").read_text())
        sequence = Path(source.get("fixture", FIXTURE)) / "sequence.yaml"
        changes["fringes"] = {
            "codings": [],
            "sequences": [str(sequence.resolve())],
            "directions": [bench["direction"]],
        }
    return changes


def dataset_config(real: Path, variant: str, num: int):
    """The template with the bench's scenes and sequence (:data:`BENCHES`), the real rig,
    the variant's devices and ``num`` samples."""
    from virtus.data import DatasetConfig
    from virtus.io.safeio import read_yaml

    data = read_yaml(TEMPLATE, "dataset config", expect=dict)
    data.update(_bench_dataset(real, bench_of(real)))
    sensors, projectors = _devices(real, variant)
    data.update(
        num_samples=num,
        sensor=sensors,
        projector=projectors,
        rig={**data.get("rig", {}), "file": str((real / "rig.json").resolve())},
    )
    return DatasetConfig.from_dict(data, base_dir=TEMPLATE.parent)


def _train_config(args: argparse.Namespace, bench: dict):
    from virtus.learn import TrainConfig

    return TrainConfig.from_dict(
        {
            "model": "phase",
            "direction": bench["direction"],
            "base_channels": args.base_channels,
            "levels": args.levels,
            "epochs": 100_000,  # max_steps decides: every variant takes the same steps
            "max_steps": args.steps,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "depth_range_m": bench["depth_range_m"],
            "depth_weight": args.depth_weight,
            "checkpoint_every": 100,
            "workers": args.loader_workers,
            "seed": 0,
        }
    )


def _progress(message: str) -> None:
    """One line at once (a run cut off at a time limit still shows how far it got)."""
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def run(args: argparse.Namespace) -> dict:
    from virtus.data import generate
    from virtus.learn import evaluate, evaluate_captures, train

    real = args.real
    if not (real / "capture" / "capture.json").is_file() or not (real / "rig.json").is_file():
        raise SystemExit(f"{real}: no prepared capture (run `prepare` first)")
    args.out.mkdir(parents=True, exist_ok=True)
    bench = bench_of(real)
    config = _train_config(args, bench)
    results, timings = {}, {}
    for variant in args.variants:
        store, run_dir = args.out / f"{variant}.zarr", args.out / f"run-{variant}"
        _progress(f"{variant}: generating {args.num} samples into {store}")
        start = time.perf_counter()
        generate(dataset_config(real, variant, args.num), store, workers=args.workers)
        timings[f"generate_{variant}_s"] = time.perf_counter() - start
        _progress(f"{variant}: generated in {timings[f'generate_{variant}_s']:.0f} s; training")
        start = time.perf_counter()

        def step_done(step: int, variant: str = variant) -> None:
            if step % 100 == 0:
                _progress(f"{variant}: step {step} of {args.steps}")

        train(config, store, run_dir, resume=True, device=args.device, on_step=step_done)
        timings[f"train_{variant}_s"] = time.perf_counter() - start
        _progress(f"{variant}: trained in {timings[f'train_{variant}_s']:.0f} s; evaluating")
        results[variant] = {
            "devices": dict(zip(("sensor", "projector"), _devices(real, variant), strict=True)),
            "test": evaluate(run_dir, store, "test", device=args.device),
            "real": evaluate_captures(run_dir, [real / "capture"], device=args.device),
        }
    return {
        "bench": bench["name"],
        "reference": bench["reference"],
        "config": config.to_dict(),
        "results": results,
        "timings_s": timings,
    }


def _fmt(value: float | None, width: int) -> str:
    return f"{value:{width}.3f}" if value is not None else f"{'-':>{width}}"


def _print(summary: dict, args: argparse.Namespace) -> None:
    print(
        f"\nsim-to-real on {summary['device']}: phase head, {args.num} samples per store, "
        f"{args.steps} steps, batch {args.batch_size}, width {args.base_channels}; real: "
        f"{args.real / 'capture'} ({summary['bench']}; reference: {summary['reference']})"
    )
    print(
        f"{'trained on':14} {'sim phase rad':>13} {'sim obj MAE mm':>15} {'real phase rad':>15} "
        f"{'real MAE mm':>12} {'real RMSE mm':>13} {'real order err':>15}"
    )
    for name, r in summary["results"].items():
        t, c = r["test"], r["real"]
        print(
            f"{name:14} {_fmt(t['phase_rmse_rad'], 13)} {_fmt(t['object_mae_mm'], 15)} "
            f"{_fmt(c['phase_rmse_rad'], 15)} {_fmt(c['object_mae_mm'], 12)} "
            f"{_fmt(c['object_rmse_mm'], 13)} {_fmt(c['order_error_rate'], 15)}"
        )
    print("timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in summary["timings_s"].items()))


def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    p = sub.add_parser("prepare", help="the compact real capture (runs here)")
    p.add_argument("source", type=Path, help="clone or bare git dir of the capture's repo")
    p.add_argument("--out", type=Path, required=True, help="e.g. .gpu-work/real")
    p.add_argument("--bin", type=int, default=4, help="binning factor (4: 484 x 366)")
    f = sub.add_parser("fixture", help="derive the committed SLMaster fixture (runs here, once)")
    f.add_argument("source", type=Path, help=f"clone or bare git dir of {SLMASTER_REPO}")
    f.add_argument("--out", type=Path, default=FIXTURE, help="default: the committed fixture")
    q = sub.add_parser("prepare-fixture", help="the run folder of the committed fixture")
    q.add_argument("fixture", type=Path, nargs="?", default=FIXTURE)
    q.add_argument("--out", type=Path, required=True, help="e.g. .gpu-work/real-slmaster")
    r = sub.add_parser("run", help="stores, training and evaluation")
    add = r.add_argument
    add("real", type=Path, help="the folder `prepare` wrote")
    add("--out", type=Path, required=True, help="folder for stores and runs")
    add("--variants", nargs="+", choices=VARIANTS, default=["realistic", "ideal"])
    add("--num", type=int, default=12, help="samples per store")
    add("--steps", type=int, default=4, help="optimiser steps (every variant)")
    add("--base-channels", type=int, default=8)
    add("--levels", type=int, default=4)
    add("--batch-size", type=int, default=2)
    add("--lr", type=float, default=1e-4)
    add("--depth-weight", type=float, default=1.0, help="phase head's depth L1 weight")
    add("--workers", type=int, default=1, help="dataset generation workers")
    add("--loader-workers", type=int, default=0, help="DataLoader workers")
    add("--device", default=None, help="torch device (default: cuda if any)")
    add("--json", type=Path, default=None)
    return parser.parse_args()


def main() -> None:
    args = _arguments()
    if args.step == "prepare":
        print(json.dumps(prepare(args.source, args.out, args.bin), indent=1, default=float))
        return
    if args.step == "fixture":
        print(json.dumps(make_fixture(args.source, args.out), indent=1))
        return
    if args.step == "prepare-fixture":
        print(json.dumps(prepare_fixture(args.fixture, args.out), indent=1, default=float))
        return
    import torch

    summary = run(args)
    cuda = torch.cuda.is_available() and args.device in (None, "cuda")
    summary["device"] = torch.cuda.get_device_name(0) if cuda else platform.platform()
    summary["args"] = {k: str(v) for k, v in vars(args).items()}
    _print(summary, args)
    if args.json:
        args.json.write_text(json.dumps(summary, indent=2, default=float))


if __name__ == "__main__":
    main()
