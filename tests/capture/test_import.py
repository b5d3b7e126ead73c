"""Real benches' data in: image folders + sequence description + calibration -> a capture
that decodes and reconstructs, and the command's refusals."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from tests.render.test_renderer import interior
from tests.support import cropped_rig, small_rig
from virtus.calib.io import save_paper_txt
from virtus.capture.capture import Capture, import_capture
from virtus.cli import main
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.patterns import default_sequence, load_sequence_file
from virtus.pipeline.scan import decode_capture, reconstruct_capture
from virtus.scanner import Scanner
from virtus.scene.model import default_scene
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import Lookup, ProjectorModel

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "sequences"


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in args])
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


@pytest.fixture(scope="module")
def twelve_bit():
    """A 12-bit capture of the default scene, as a real camera would store it: numbers up
    to 4095 in 16-bit files."""
    scanner = Scanner(
        rig=small_rig(),
        sensor=Sensor(bit_depth=12),
        projector=ProjectorModel(pixel=Lookup.bilinear),
    )
    return scanner, scanner.capture(default_scene())


def _export(frames: np.ndarray, folder: Path, pattern: str) -> Path:
    folder.mkdir(parents=True)
    for index, frame in enumerate(frames):
        assert cv2.imwrite(str(folder / pattern.format(index)), frame)
    return folder


def _row_pair_rig(rig: Rig) -> Rig:
    """``rig`` with its projector's 1140 DMD rows counted in pairs (912 x 570 px, each row
    pair as tall as a column is wide), as the lab's sequence file describes them."""
    k = rig.projector.intrinsics
    pairs = Intrinsics(k.fx, k.fy / 2, k.cx, (k.height / 2 - 1) / 2, k.width, k.height // 2)
    return Rig(rig.camera, Projector(pairs), rig.proj2cam)


def _decoded_error(capture: Capture, decoded) -> np.ndarray:
    """Decoded minus true projector coordinates (px) of the pixels the decode vouches for
    (valid, not flagged), away from silhouettes, where a pixel's supersamples see one
    surface (mixed pixels are the reconstruction's edge filter's job)."""
    gt = capture.ground_truth
    depth = np.where(gt.mask, gt.depth, 1e9)  # off-mask pixels: a far, distinct depth
    smooth = np.ones_like(gt.mask)
    for axis in (0, 1):
        step = np.abs(np.diff(depth, axis=axis)) < 1e-3
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        smooth &= np.pad(step, pad, constant_values=False)
        pad[axis] = (0, 1)
        smooth &= np.pad(step, pad, constant_values=False)
    valid = decoded.mask & interior(gt.mask & smooth) & ~decoded.flagged
    return (decoded.proj_uv[valid] - gt.proj_uv[valid]).ravel()


@pytest.mark.parametrize(("suffix", "pattern"), [(".tif", "img{}.tif"), (".png", "frame_{}.png")])
def test_imported_frames_decode_like_the_originals(tmp_path, twelve_bit, suffix, pattern) -> None:
    scanner, rendered = twelve_bit
    frames = rendered.frames if suffix == ".tif" else rendered.frames * np.uint16(16)
    # Natural order: img2 before img10 (a lexical sort would scramble the sequence).
    folder = _export(frames, tmp_path / "images", pattern)
    imported = import_capture(folder, scanner.sequence, scanner.rig)
    assert imported.bit_depth == (12 if suffix == ".tif" else 16)
    np.testing.assert_array_equal(imported.frames, frames)
    decoded = imported.decode()
    reference = rendered.decode()
    # Same decode; with numbers scaled x16 into 16 bits the modulation threshold (a fraction
    # of full scale) moves by 16/65535 vs 1/4095 of it: a pixel on the threshold may differ.
    assert np.mean(decoded.mask != reference.mask) < 1e-3
    error = _decoded_error(rendered, decoded)
    assert np.sqrt(np.mean(error**2)) < tol.DECODE_RENDERED_BILINEAR_PX
    # Saved, it reloads as an equal capture, without ground truth.
    loaded = Capture.load(imported.save(tmp_path / "cap").parent)
    assert loaded == imported and not loaded.has_ground_truth
    assert loaded.provenance["source"] == "imported"


def test_import_command_then_decode_and_reconstruct(tmp_path, twelve_bit, capsys) -> None:
    scanner, rendered = twelve_bit
    folder = _export(rendered.frames, tmp_path / "bench", "{:02d}.tiff")
    sequence_file = tmp_path / "sequence.json"
    sequence_file.write_text(json.dumps(scanner.sequence.to_dict()))
    calibration = save_paper_txt(scanner.rig, tmp_path / "txt")  # mm, as the paper's code
    out = tmp_path / "cap"
    code, stdout, stderr = run_cli(
        ["import", folder, "--sequence", sequence_file, "--calibration", calibration,
         "--out", out],
        capsys,
    )  # fmt: skip
    assert code == 0, stderr
    assert "12-bit" in stdout
    code, stdout, stderr = run_cli(["decode", out], capsys)
    assert code == 0, stderr and "flagged" in stdout
    recon = reconstruct_capture(out)
    gt = rendered.ground_truth
    both = recon.mask & gt.mask
    depth_error = np.abs(recon.depth[both] - gt.depth[both])
    assert both.mean() > 0.5 and np.median(depth_error) < tol.IMPORTED_DEPTH_M


def test_lab_sequence_decodes_and_a_wrong_description_is_flagged(tmp_path, capsys) -> None:
    # The lab's sequence: binary fringes, Gray codes LSB first aligned to the fringe edges,
    # no complementary frame, four black frames (examples/sequences/lightcrafter_lab.yaml).
    sequence, _ = load_sequence_file(EXAMPLES / "lightcrafter_lab.yaml")
    assert len(sequence) == 52
    # The paper's pixel footprint on the object (a 160 px camera over the same field sees
    # ~4 camera px per fringe and blurs the codes over 5 projector px).
    scanner = Scanner(
        rig=_row_pair_rig(cropped_rig(320)),
        sequence=sequence,
        projector=ProjectorModel(pixel=Lookup.bilinear),
    )
    rendered = scanner.capture(default_scene())
    folder = _export(rendered.frames, tmp_path / "lab", "{}.bmp")
    imported = import_capture(folder, sequence, scanner.rig)
    decoded = imported.decode()
    assert decoded.mask.mean() > 0.5
    assert decoded.flagged[decoded.mask].mean() < tol.FLAGGED_SHARE_CLEAN
    error = _decoded_error(rendered, decoded)
    assert np.sqrt(np.mean(error**2)) < tol.DECODE_LAB_BINARY_PX
    # Codes without the complement misread some pixels at their edges: the decode flags them
    # (it says when it is wrong) and no unflagged pixel is off by half a period.
    assert np.abs(error).max() < 9.0

    # The same frames described with the bit order swapped: flagged, and the command warns.
    wrong = json.loads(json.dumps(sequence.to_dict()))
    for frame in wrong["frames"]:
        if frame["kind"] == "gray":  # the frame showing bit b is described as bit B + 1 - b
            frame["bit"] = frame["bits"] + 1 - frame["bit"]
    wrong_file = tmp_path / "wrong.json"
    wrong_file.write_text(json.dumps(wrong))
    rig_file = scanner.rig.save_json(tmp_path / "rig.json")
    out = tmp_path / "wrong_cap"
    code, _, stderr = run_cli(
        ["import", folder, "--sequence", wrong_file, "--calibration", rig_file, "--out", out],
        capsys,
    )
    assert code == 0, stderr
    code, _, stderr = run_cli(["decode", out], capsys)
    assert "virtus: warning:" in stderr and "flagged" in stderr
    summary = json.loads((out / "decoded" / "summary.json").read_text())
    flagged = np.load(out / "decoded" / "flagged.npy")
    mask = np.load(out / "decoded" / "mask.npy")
    assert flagged[mask].mean() > 0.2 and summary


def test_decoded_files_are_recomputed_when_the_frames_change(tmp_path, twelve_bit) -> None:
    _, rendered = twelve_bit
    directory = tmp_path / "cap"
    rendered.save(directory)
    decode_capture(directory)
    first = reconstruct_capture(directory).points
    # Replace the frames by black ones: the stale decode must not be reused (and a decode
    # of black frames is an error that says so, not an empty reconstruction).
    for path in sorted((directory / "frames").glob("*.png")):
        cv2.imwrite(str(path), np.zeros(rendered.frames.shape[1:], np.uint16))
    assert np.isfinite(first).any()
    with pytest.raises(VirtusError, match="every frame is black"):
        reconstruct_capture(directory)


def _bad_import_cases(tmp_path: Path, twelve_bit) -> dict[str, tuple[list, str]]:
    scanner, rendered = twelve_bit
    good = _export(rendered.frames, tmp_path / "good", "{:03d}.png")
    short = _export(rendered.frames[:-1], tmp_path / "short", "{:03d}.png")
    mixed = _export(rendered.frames, tmp_path / "mixed", "{:03d}.png")
    cv2.imwrite(str(mixed / "007.png"), np.zeros((10, 12), np.uint16))
    seq = tmp_path / "seq.json"
    seq.write_text(json.dumps(scanner.sequence.to_dict()))
    rig = scanner.rig.save_json(tmp_path / "rig.json")
    no_units = tmp_path / "calib.yaml"
    fs = cv2.FileStorage(str(no_units), cv2.FILE_STORAGE_WRITE)
    cam, prj = scanner.rig.camera.intrinsics, scanner.rig.projector.intrinsics
    for key, value in (("K1", cam.K), ("D1", np.zeros((1, 5))), ("K2", prj.K),
                       ("D2", np.zeros((1, 5))), ("R", scanner.rig.cam2proj.R),
                       ("T", scanner.rig.cam2proj.t.reshape(3, 1) * 1000)):  # fmt: skip
        fs.write(key, value)
    fs.release()
    not_rotation = json.loads(rig.read_text())
    not_rotation["proj2cam"]["R"] = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]
    bad_rotation = tmp_path / "bad_rotation.json"
    bad_rotation.write_text(json.dumps(not_rotation))

    def sequence_file(name: str, edit) -> Path:  # noqa: ANN001
        data = scanner.sequence.to_dict()
        edit(data)
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(data))
        return path

    def set_first(key: str, value: object):  # noqa: ANN202
        return lambda data: data["frames"][0].__setitem__(key, value)

    def drop_gray_bit(data: dict) -> None:
        kept = [f for f in data["frames"] if not (f["kind"] == "gray" and f.get("bit") == 6)]
        data["frames"] = [{**f, "index": i} for i, f in enumerate(kept)]

    def args(images: Path, sequence: Path, calibration: Path) -> list:
        return ["import", images, "--sequence", sequence, "--calibration", calibration,
                "--out", tmp_path / "out"]  # fmt: skip

    return {
        "unknown coding": (args(good, sequence_file("kind", set_first("kind", "wavelet")), rig),
                           "kind"),
        "N < 3": (args(good, sequence_file("steps", set_first("steps", 2)), rig), "steps"),
        "period <= 0": (args(good, sequence_file("period", set_first("period", 0)), rig),
                        "period"),
        "too few bits": (args(good, sequence_file("bits", drop_gray_bit), rig), "bit"),
        "image count": (args(short, seq, rig), "52 images"),
        "image sizes": (args(mixed, seq, rig), "one size"),
        "no units": (args(good, seq, no_units), "units"),
        "not a rotation": (args(good, seq, bad_rotation), "rotation"),
    }  # fmt: skip


@pytest.mark.parametrize(
    "case",
    ["unknown coding", "N < 3", "period <= 0", "too few bits", "image count", "image sizes",
     "no units", "not a rotation"],
)  # fmt: skip
def test_bad_imports_are_one_line_and_write_nothing(tmp_path, twelve_bit, capsys, case) -> None:
    args, needle = _bad_import_cases(tmp_path, twelve_bit)[case]
    code, _, stderr = run_cli(args, capsys)
    lines = stderr.strip().splitlines()
    assert code == 2 and len(lines) == 1, stderr
    assert lines[0].startswith("virtus: error: ") and needle in lines[0], lines[0]
    assert "Traceback" not in stderr
    assert not (tmp_path / "out").exists()


def test_bit_depth_is_checked_against_the_data(tmp_path, twelve_bit) -> None:
    scanner, rendered = twelve_bit
    folder = _export(rendered.frames, tmp_path / "images", "{:03d}.png")
    for stated in (10, 8, 14):
        with pytest.raises(InputError, match="^bit_depth: expected"):
            import_capture(folder, scanner.sequence, scanner.rig, bit_depth=stated)
    capture = Capture(scanner.sequence, scanner.rig, frame_data=rendered.frames)
    assert capture.bit_depth == 12 and capture.full_scale == 4095
    with pytest.raises(InputError, match="^frames: expected 52 frames"):
        Capture(default_sequence(), scanner.rig, frame_data=rendered.frames[:10])
