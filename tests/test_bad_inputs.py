"""A corpus of bad inputs, over every command and file type: each ends as exit status 2 and
exactly one ``virtus: error:`` line on stderr naming the problem, with no traceback and no
output written (the output directory absent, every existing file unchanged).

The cases are tables: ``(id, files, argv, message)``. ``files`` maps names in the case's
work directory to their content (text, bytes or a builder); ``argv`` may use ``{w}`` (the
work directory), ``{rig}`` (a valid tiny rig: a 64 x 48 camera), ``{cap}`` (a fresh copy of
a tiny rendered capture, decoded and reconstructed), ``{out}`` (an output directory that
must not appear). Cases that would render fail before rendering (each is a few ms).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from virtus.cli import main
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.io.runs import directory_lock

# --- builders of the work directory's files --------------------------------------------------


def _rig_dict(**changes: object) -> dict:
    """The tiny rig (64 x 48 camera, the paper's projector) as JSON, with changes applied
    at dotted keys (``camera.width``)."""
    rig = default_rig()
    cam = rig.camera.intrinsics
    tiny = Intrinsics(cam.fx / 15, cam.fy / 15, 31.5, 23.5, 64, 48)
    data = Rig(Camera(tiny), rig.projector, rig.proj2cam).to_dict()
    for key, value in changes.items():
        *path, last = key.split(".")
        node = data
        for part in path:
            node = node[part]
        if value is _DELETE:
            del node[last]
        else:
            node[last] = value
    return data


_DELETE = object()


def rig(**changes: object) -> str:
    return json.dumps(_rig_dict(**changes))


def deep(levels: int, kind: str = "json") -> str:
    return (
        "[" * levels + "]" * levels
        if kind == "json"
        else "a:\n" + "".join("  " * i + "- " + "\n" for i in range(levels))
    )


ALIAS_BOMB = "a: &a [x,x,x,x,x,x,x,x,x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{','.join([f'*{chr(97 + i)}'] * 9)}]\n" for i in range(8)
)
RECURSIVE = "objects: &o\n  - *o\n"
SPHERE = "objects:\n  - {type: sphere, radius_m: 0.1, center_m: [0, 0, 1]}\n"


def mesh_scene(obj_text: str) -> dict:
    return {
        "m.obj": obj_text,
        "s.yaml": "objects:\n  - {type: mesh, path: m.obj, pose: {t: [0, 0, 1]}}\n",
    }


def npy_bytes(array: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def truncated_npy(shape=(48, 64, 2), dtype=np.float64) -> bytes:
    return npy_bytes(np.zeros(shape, dtype))[:-100]


def pickled_npy() -> bytes:
    return pickle.dumps([1, 2])


def object_npy() -> bytes:
    data = npy_bytes(np.zeros((2,), dtype=np.float64))
    return data.replace(b"'<f8'", b"'|O' ")


def png(shape=(48, 64), value=0, dtype=np.uint8, channels=1) -> bytes:
    image = np.full(shape if channels == 1 else (*shape, channels), value, dtype)
    if channels == 3:
        image[..., 0] = 7
    return cv2.imencode(".png", image)[1].tobytes()


def ply(header: str, body: bytes = b"") -> bytes:
    return header.encode() + body


PLY_OK_HEADER = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
PLY_XYZ = "property float y\nproperty float z\nend_header\n"


def opencv_yaml(body: str) -> str:
    return "%YAML:1.0\n---\n" + body


def paper_txt(**replace: str) -> dict:
    """The paper code's text files for the tiny rig (in mm), some replaced."""
    from virtus.calib.io import save_paper_txt

    files: dict = {}

    def build(work: Path) -> None:
        folder = work / "txt"
        save_paper_txt(Rig.from_dict(_rig_dict()), folder)
        for name, text in replace.items():
            if text is None:
                (folder / name).unlink()
            else:
                (folder / name).write_text(text)

    files["txt"] = build
    return files


def capture_edit(edit: Callable[[Path], None]) -> dict:
    """Files entry that edits the copy of the tiny capture."""
    return {"__cap__": edit}


def set_json(name: str, change: Callable[[dict], object]) -> Callable[[Path], None]:
    def edit(cap: Path) -> None:
        path = cap / name
        data = json.loads(path.read_text())
        change(data)
        path.write_text(json.dumps(data))

    return edit


def write(name: str, content: bytes | str) -> Callable[[Path], None]:
    def edit(cap: Path) -> None:
        target = cap / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, str):
            target.write_text(content)
        else:
            target.write_bytes(content)

    return edit


def frames(value: int) -> Callable[[Path], None]:
    """Replace every frame by a flat image of ``value`` (digital numbers)."""

    def edit(cap: Path) -> None:
        for path in sorted((cap / "frames").glob("*.png")):
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            cv2.imwrite(str(path), np.full_like(image, min(value, np.iinfo(image.dtype).max)))

    return edit


def scaled_frames(cap: Path) -> None:
    """Frames divided by 64 (a 16-bit capture written as if 10-bit data were 16-bit)."""
    data = json.loads((cap / "capture.json").read_text())
    data["bit_depth"] = 16
    (cap / "capture.json").write_text(json.dumps(data))
    for path in sorted((cap / "frames").glob("*.png")):
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(path), (image // 64).astype(np.uint16))


def import_images(count: int = 52, **kwargs: object) -> Callable[[Path], None]:
    def build(work: Path) -> None:
        folder = work / "images"
        folder.mkdir()
        for i in range(count):
            (folder / f"img{i}.png").write_bytes(png(**kwargs))

    return build


def import_sequence(work: Path) -> None:
    from virtus.patterns import default_sequence

    sequence = default_sequence(912, 1140)
    (work / "seq.json").write_text(json.dumps(sequence.to_dict()))


# --- the cases --------------------------------------------------------------------------------

C = "capture"
CO = [C, "--rig", "{rig}", "--out", "{out}"]  # a capture that would render if nothing failed
SC = ["scan", "--rig", "{rig}", "--out", "{out}"]
CAL = ["calibrate", "--rig", "{rig}", "--out", "{out}"]
DEMO = ["demo", "--rig", "{rig}", "--out", "{out}"]
ABL = ["ablation", "--rig", "{rig}", "--out", "{out}"]
IMP = ["import", "{w}/images", "--sequence", "{w}/seq.json", "--calibration", "{w}/rig.json",
       "--out", "{out}"]  # fmt: skip
IMPORT_OK = {"images": import_images(), "seq.json": import_sequence, "rig.json": rig()}

CLI_OPTIONS = [
    # (id, argv, message): negative, huge, non-numeric values, unknown choices, missing args
    ("no-command", ["frobnicate"], "No such command"),
    ("capture-unknown-option", [*CO, "--colour"], "No such option"),
    ("capture-spp-text", [*CO, "--spp", "four"], "Invalid value for '--spp'"),
    ("capture-spp-zero", [*CO, "--spp", "0"], "spp: expected an integer >= 1"),
    ("capture-spp-negative", [*CO, "--spp", "-4"], "spp: expected an integer >= 1"),
    ("capture-spp-huge", [*CO, "--spp", "1000000000000"], "spp: expected at most 1024"),
    ("capture-spp-not-square", [*CO, "--spp", "3"], "spp: expected a perfect square"),
    ("capture-spp-float", [*CO, "--spp", "2.5"], "Invalid value for '--spp'"),
    ("capture-seed-negative", [*CO, "--seed", "-1"], "seed: expected an integer in 0.."),
    ("capture-seed-huge", [*CO, "--seed", str(2**70)], "seed"),
    ("capture-bit-depth", [*CO, "--bit-depth", "14"], "bit_depth: expected one of"),
    ("capture-bit-depth-negative", [*CO, "--bit-depth", "-8"], "bit_depth"),
    ("capture-lookup", [*CO, "--lookup", "cubic"], "'cubic' is not one of"),
    ("capture-sensor-preset", [*CO, "--sensor", "nosuch"], "sensor"),
    ("capture-projector-preset", [*CO, "--projector", "nosuch"], "projector"),
    ("capture-bounces-zero", [*CO, "--bounces", "0"], "bounces: expected an integer in 1..8"),
    ("capture-bounces-huge", [*CO, "--bounces", "100"], "bounces: expected an integer in 1..8"),
    ("capture-variant", [*CO, "--variant", "scalar_rgb"], "variant: expected one of"),
    ("capture-lens-text", [*CO, "--projector-lens", "wide"], "--projector-lens: expected"),
    ("capture-lens-three", [*CO, "--camera-lens", "1,2,3"], "--camera-lens: expected"),
    ("capture-lens-negative", [*CO, "--camera-lens", "-0.01,1"], "aperture"),
    ("capture-scene-missing", [*CO, "--scene", "{w}/nope.yaml"], "scene: expected an existing"),
    ("capture-rig-missing", [C, "--rig", "{w}/nope.json", "--out", "{out}"], "rig: expected an"),
    ("capture-sequence-missing", [*CO, "--sequence", "{w}/nope.yaml"], "expected"),
    ("capture-overwrite-and-resume", [*CO, "--overwrite", "--resume"], "at most one of them"),
    ("capture-memory", [C, "--out", "{out}", "--spp", "16", "--bounces", "8", "--projector-lens",
                        "0.01,1"], "memory: expected at most 8 GiB"),
    ("scan-memory", ["scan", "--out", "{out}", "--spp", "64", "--bounces", "8",
                     "--projector-lens", "0.01,1"], "memory: expected at most 8 GiB"),
    ("scan-turntable-negative", [*SC, "--turntable", "-3"], "turntable views (--turntable)"),
    ("scan-turntable-huge", [*SC, "--turntable", "100000"], "at most 360 views"),
    ("scan-turntable-sphere", [*SC, "--turntable", "4"], "exactly one mesh object"),
    ("scan-scene-unknown", [*SC, "--scene", "cube"], "scene: expected an existing scene YAML"),
    ("scan-units", [*SC, "--units", "inch"], "'inch' is not one of"),
    ("scan-spp-huge", [*SC, "--spp", "1000000000000"], "spp: expected at most 1024"),
    ("scan-seed-negative", [*SC, "--seed", "-7"], "seed"),
    ("scan-calibration-missing", [*SC, "--calibration", "{w}/nope.json"], "nope.json"),
    ("scan-bounces-text", [*SC, "--bounces", "two"], "Invalid value for '--bounces'"),
    ("calibrate-board", [*CAL, "--board", "4x6"], "cols: expected an odd number"),
    ("calibrate-board-text", [*CAL, "--board", "big"], "board"),
    ("calibrate-poses-few", [*CAL, "--poses", "random:1"], "poses: expected 'paper' or"),
    ("calibrate-poses-huge", [*CAL, "--poses", "random:100000"], "poses: expected 'paper' or"),
    ("calibrate-poses-word", [*CAL, "--poses", "many"], "poses: expected 'paper' or"),
    ("calibrate-seed-negative", [*CAL, "--seed", "-1"], "seed"),
    ("calibrate-spp-huge", [*CAL, "--spp", "1000000000000"], "spp: expected at most 1024"),
    ("demo-spp-zero", [*DEMO, "--spp", "0"], "spp: expected an integer >= 1"),
    ("demo-spp-not-square", [*DEMO, "--spp", "8"], "spp: expected a perfect square"),
    ("demo-lookup", [*DEMO, "--lookup", "sinc"], "'sinc' is not one of"),
    ("demo-bounces", [*DEMO, "--bounces", "-1"], "bounces"),
    ("demo-variant", [*DEMO, "--variant", "gpu"], "variant: expected one of"),
    ("ablation-material", [*ABL, "--materials", "velvet"], "materials (--materials)"),
    ("ablation-ambient", [*ABL, "--ambient", "noon"], "ambients (--ambient)"),
    ("ablation-realism", [*ABL, "--realism", "magic"], "realism (--realism)"),
    ("ablation-empty", [*ABL, "--materials", ","], "materials (--materials)"),
    ("ablation-spp", [*ABL, "--spp", "-1"], "spp"),
    ("ablation-seed", [*ABL, "--seed", "-1"], "seed"),
    ("patterns-width-negative", ["patterns", "--out", "{out}", "--width", "-5"], "width"),
    ("patterns-width-huge", ["patterns", "--out", "{out}", "--width", "100000000"], "width"),
    ("patterns-height-text", ["patterns", "--out", "{out}", "--height", "tall"], "'--height'"),
    ("rig-info-pixel-size", ["rig", "info", "--pixel-size-mm", "abc"], "'--pixel-size-mm'"),
    ("rig-no-subcommand", ["rig", "inspect"], "No such command"),
    ("decode-missing-arg", ["decode"], "Missing argument"),
    ("decode-not-a-capture", ["decode", "{w}"], "capture: expected a directory holding"),
    ("decode-missing-dir", ["decode", "{w}/nope"], "capture: expected a directory holding"),
    ("decode-modulation-text", ["decode", "{cap}", "--min-modulation", "x"], "Invalid value"),
    ("reconstruct-use", ["reconstruct", "{cap}", "--use", "w"], "'w' is not one of"),
    ("reconstruct-missing-dir", ["reconstruct", "{w}/nope"], "capture: expected a directory"),
    ("reconstruct-calibration-missing",
     ["reconstruct", "{cap}", "--calibration", "{w}/nope.json"], "nope.json"),
    ("evaluate-missing-arg", ["evaluate"], "Missing argument"),
    ("evaluate-missing-ply", ["evaluate", "{cap}", "--ply", "{w}/nope.ply"], "no point cloud"),
    ("import-missing-sequence",
     ["import", "{w}", "--calibration", "{w}/r.json", "--out", "{out}"], "Missing option"),
    ("import-missing-images", [*IMP[:1], "{w}/none", *IMP[2:]], "seq.json"),
    # run ownership: a directory holding another run's files is refused, nothing touched
    ("capture-into-unrecorded-capture", [C, "--rig", "{rig}", "--out", "{cap}"],
     "holds files of an earlier run without run.json"),
    ("scan-into-unrecorded-capture", ["scan", "--rig", "{rig}", "--out", "{cap}"],
     "holds files of an earlier run without run.json"),
]  # fmt: skip

# Rig JSON, read by every command that takes --rig (and as a calibration file).
RIG_FILES = [
    ("rig-not-utf8", b'{"camera": "\xff\xfe"}', "not UTF-8 text"),
    ("rig-binary", b"\x00\x01\x02\x03", "a binary file"),
    ("rig-empty", b"", "bad.json"),
    ("rig-deep", deep(100), "JSON nested at most 64 deep"),
    ("rig-list", "[1, 2, 3]", "expected a JSON object, got 'a JSON array'"),
    ("rig-string", '"rig"', "expected a JSON object"),
    ("rig-syntax", '{"camera": {', "valid JSON"),
    ("rig-nan", rig().replace('"width": 64', '"width": NaN'), "NaN or Infinity"),
    ("rig-duplicate-key", '{"camera": 1, "camera": 2}', "key 'camera' twice"),
    ("rig-huge-camera", rig(**{"camera.width": 100000, "camera.height": 100000}), "width"),
    ("rig-misspelt-dist", rig(**{"camera.distortion": [0, 0, 0, 0, 0]}), "did you mean 'dist'"),
    ("rig-missing-camera", rig(camera=_DELETE), "camera"),
    ("rig-missing-K", rig(**{"camera.K": _DELETE}), "K"),
    ("rig-negative-width", rig(**{"camera.width": -64}), "width"),
    ("rig-float-width", rig(**{"camera.width": 64.5}), "width"),
    ("rig-K-shape", rig(**{"camera.K": [[1, 0], [0, 1]]}), "K"),
    ("rig-K-skew", rig(**{"camera.K": [[100, 5, 30], [0, 100, 20], [0, 0, 1]]}), "K"),
    ("rig-K-text", rig(**{"camera.K": "identity"}), "K"),
    ("rig-dist-length", rig(**{"camera.dist": [0.1] * 9}), "at most 8 coefficients"),
    ("rig-R-not-rotation", rig(**{"proj2cam.R": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}), "R"),
    ("rig-t-length", rig(**{"proj2cam.t": [0.1, 0.2]}), "t"),
    ("rig-units", rig(units="furlong"), "units"),
    ("rig-huge-number", rig(**{"camera.K": [[1e400, 0, 1], [0, 1, 1], [0, 0, 1]]}), "finite"),
    ("rig-projector-missing", rig(projector=_DELETE), "projector"),
]  # fmt: skip

SCENES = [
    ("scene-alias-bomb", ALIAS_BOMB, "an alias bomb"),
    ("scene-recursive", RECURSIVE, "no recursive YAML anchors"),
    ("scene-not-utf8", b"objects: [\xff]", "not UTF-8 text"),
    ("scene-binary", b"\x00objects", "a binary file"),
    ("scene-empty", "", "scene"),
    ("scene-list", "- 1\n- 2\n", "expected a YAML mapping"),
    ("scene-deep", deep(100, "yaml"), "YAML nested at most 64 deep"),
    ("scene-syntax", "objects: [\n", "valid YAML"),
    ("scene-tab", "objects:\n\t- 1\n", "valid YAML"),
    ("scene-duplicate", SPHERE + SPHERE, "each key once"),
    ("scene-unknown-key", SPHERE + "lights_on: true\n", "lights_on"),
    ("scene-no-objects", "objects: []\n", "expected at least one object"),
    ("scene-radius-huge", SPHERE.replace("0.1,", "1e300,"), "radius"),
    ("scene-radius-negative", SPHERE.replace("0.1,", "-0.1,"), "radius"),
    ("scene-radius-nan", SPHERE.replace("0.1,", ".nan,"), "finite"),
    ("scene-behind", SPHERE.replace("[0, 0, 1]", "[0, 0, -1]"), "in front of the camera"),
    ("scene-unknown-type", "objects:\n  - {type: torus}\n", "torus"),
    ("scene-mesh-missing", "objects:\n  - {type: mesh, path: none.obj}\n", "existing mesh"),
    ("scene-mesh-suffix", "objects:\n  - {type: mesh, path: m.txt}\n", "a mesh file"),
    ("scene-int-huge", "objects:\n  - {type: sphere, radius_m: 1" + "0" * 400 + "}\n", "float64"),
]  # fmt: skip

MESHES = [
    ("mesh-nan", "v nan 0 0\nv 0 0.1 0\nv 0.1 0 0\nf 1 2 3\n", "non-finite"),
    ("mesh-empty", "# nothing\n", "mesh"),
    ("mesh-degenerate", "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n", "area"),
    ("mesh-index", "v 0 0 0\nv 0 0.1 0\nv 0.1 0 0\nf 1 2 9\n", "mesh"),
    ("mesh-huge", "v 1e300 0 0\nv 0 1e300 0\nv 0 0 1e300\nf 1 2 3\n", "mesh"),
]  # fmt: skip

SEQUENCES = [
    ("sequence-empty", "", "sequence"),
    ("sequence-list", "[1, 2]\n", "sequence"),
    ("sequence-not-utf8", b"width: \xff", "expected UTF-8 text"),
    ("sequence-bomb", ALIAS_BOMB, "sequence"),
    ("sequence-unknown-key", "width: 912\nheight: 1140\nframez: []\n", "framez"),
    ("sequence-negative-width", "width: -912\nheight: 1140\nframes: []\n", "width"),
]  # fmt: skip

DEVICE_FILES = [
    # (id, option, content, message)
    ("sensor-unknown-key", "--sensor", "bit_depht: 12\n", "did you mean 'bit_depth'"),
    ("sensor-bad-depth", "--sensor", "bit_depth: 9\n", "bit_depth"),
    ("sensor-negative-gain", "--sensor", "system_gain: -1\n", "system_gain"),
    ("sensor-list", "--sensor", "- 1\n", "expected a YAML mapping"),
    ("sensor-not-utf8", "--sensor", b"\xff\xfe", "not UTF-8 text"),
    ("sensor-bomb", "--sensor", ALIAS_BOMB, "an alias bomb"),
    ("projector-unknown-key", "--projector", "gama: 2.2\n", "did you mean 'gamma'"),
    ("projector-negative-gamma", "--projector", "gamma: -2\n", "gamma"),
    ("projector-pixel", "--projector", "pixel: cubic\n", "got 'cubic'"),
    ("projector-binary", "--projector", b"\x00\x00", "a binary file"),
    ("projector-deep", "--projector", deep(100, "yaml"), "YAML nested"),
]  # fmt: skip

# Calibration files of each format, for `reconstruct --calibration` on a capture.
ZERO_BASELINE = rig(**{"proj2cam.t": [0.0, 0.0, 0.0]})
CALIBRATIONS = [
    ("calibration-zero-baseline", {"c.json": ZERO_BASELINE}, "c.json", "baseline is 0 um"),
    ("calibration-tiny-baseline",
     {"c.json": rig(**{"proj2cam.t": [1e-9, 0.0, 0.0]})}, "c.json", "baseline is 0.001 um"),
    ("calibration-list", {"c.json": "[]"}, "c.json", "expected a JSON object"),
    ("calibration-other-camera", {"c.json": rig(**{"camera.width": 32})}, "c.json", "camera"),
    ("calibration-suffix", {"c.ini": "[rig]"}, "c.ini", "c.ini"),
    ("opencv-yaml-garbage", {"c.yaml": opencv_yaml("K: [1, 2\n")}, "c.yaml", "c.yaml"),
    ("opencv-yaml-empty", {"c.yaml": opencv_yaml("")}, "c.yaml", "c.yaml"),
    ("opencv-yaml-no-matrix", {"c.yaml": opencv_yaml("foo: 1\n")}, "c.yaml", "c.yaml"),
    ("opencv-yaml-bomb", {"c.yaml": ALIAS_BOMB}, "c.yaml", "c.yaml"),
    ("opencv-yaml-bad-matrix",
     {"c.yaml": opencv_yaml("cameraMatrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n"
                            "  data: [1, 2]\n")}, "c.yaml", "c.yaml"),
    ("opencv-xml-garbage", {"c.xml": "<opencv_storage><K>"}, "c.xml", "c.xml"),
    ("opencv-xml-empty", {"c.xml": ""}, "c.xml", "c.xml"),
    ("opencv-xml-entity-bomb",
     {"c.xml": '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaaaaaaaa">'
               '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><opencv_storage><K>&b;</K>'
               "</opencv_storage>"}, "c.xml", "c.xml"),
    ("opencv-xml-binary", {"c.xml": b"\x00\x01<opencv_storage>"}, "c.xml", "c.xml"),
    ("paper-txt-missing-file", paper_txt(**{"ProjRotationMatrix.txt": None}), "txt",
     "ProjRotationMatrix.txt"),
    ("paper-txt-text", paper_txt(**{"CamIntrinsicMatrix.txt": "a\tb\tc\n"}), "txt",
     "CamIntrinsicMatrix.txt"),
    ("paper-txt-shape", paper_txt(**{"ProjRotationMatrix.txt": "1\t0\n0\t1\n"}), "txt",
     "ProjRotationMatrix.txt"),
    ("paper-txt-nan", paper_txt(**{"ProjTranslationVector.txt": "nan\n0\n0\n"}), "txt",
     "ProjTranslationVector.txt"),
    ("paper-txt-zero-baseline", paper_txt(**{"ProjTranslationVector.txt": "0\n0\n0\n"}), "txt",
     "baseline is 0 um"),
]  # fmt: skip

# capture.json, frames, gt/ and decoded/ of a capture, for decode / reconstruct / evaluate.
CAPTURE_EDITS = [
    # (id, edit, commands, message)
    ("capture-json-list", write("capture.json", "[]"), "dre", "expected a JSON object"),
    ("capture-json-empty", write("capture.json", ""), "dre", "valid JSON"),
    ("capture-json-binary", write("capture.json", b"\x00\xff"), "dre", "a binary file"),
    ("capture-json-not-utf8", write("capture.json", b'{"a": "\xff"}'), "dre", "not UTF-8"),
    ("capture-json-deep", write("capture.json", deep(200)), "dre", "nested at most 64"),
    ("capture-json-no-rig", set_json("capture.json", lambda d: d.pop("rig")), "dre", "rig"),
    ("capture-json-no-sequence", set_json("capture.json", lambda d: d.pop("sequence")), "dre",
     "sequence"),
    ("capture-json-no-frames", set_json("capture.json", lambda d: d.pop("frames")), "dre",
     "frames"),
    ("capture-json-format", set_json("capture.json", lambda d: d.update(format="v9")), "dre",
     "format"),
    ("capture-json-unknown-key", set_json("capture.json", lambda d: d.update(colour=1)), "dre",
     "colour"),
    ("capture-json-escape",
     set_json("capture.json", lambda d: d["frames"]["files"].__setitem__(0, "../../x.png")),
     "dre", "relative file names inside the capture"),
    ("capture-json-few-frames",
     set_json("capture.json", lambda d: d["frames"]["files"].pop()), "dre", "frames"),
    ("capture-json-seed", set_json("capture.json", lambda d: d.update(seed=-3)), "dre", "seed"),
    ("capture-json-bit-depth", set_json("capture.json", lambda d: d.update(bit_depth=9)), "dre",
     "bit_depth"),
    ("capture-json-huge-camera",
     set_json("capture.json", lambda d: d["rig"]["camera"].update(width=100000, height=100000)),
     "dre", "width"),
    ("frame-missing", lambda c: (c / "frames" / "000.png").unlink(), "dre", "missing"),
    ("frame-corrupt", write("frames/003.png", b"not a png"), "dr", "003.png"),
    ("frame-size", write("frames/003.png", png((20, 20))), "dr", "images of one size"),
    ("frame-colour", write("frames/003.png", png(channels=3)), "dr", "a colour image"),
    ("frames-black", frames(0), "dr", "every frame is black"),
    ("frames-saturated", frames(65535), "dr", "saturated"),
    ("frames-flat", frames(100), "dr", "one flat value"),
    ("frames-wrongly-scaled", scaled_frames, "d", "below --min-modulation"),
    ("gt-truncated", write("gt/proj_uv.npy", truncated_npy()), "d", "truncated"),
    ("gt-pickled", write("gt/mask.npy", pickled_npy()), "d", "pickle"),
    ("gt-object", write("gt/depth.npy", object_npy()), "d", "pickled arrays are refused"),
    ("gt-shape", write("gt/depth.npy", npy_bytes(np.zeros((3, 3)))), "d", "depth"),
    ("decoded-truncated", write("decoded/proj_uv.npy", truncated_npy()), "r", "truncated"),
    ("decoded-pickled", write("decoded/mask.npy", pickled_npy()), "r", "pickle"),
    ("decoded-shape", write("decoded/proj_uv.npy", npy_bytes(np.zeros((4, 4, 2)))), "r",
     "shape"),
    ("decoded-dtype", write("decoded/mask.npy", npy_bytes(np.zeros((48, 64)))), "r",
     "dtype bool"),
    ("decoded-source-list", write("decoded/source.json", "[]"), "r", "expected a JSON object"),
    ("points-ply-stale", write("points.ply", ply(PLY_OK_HEADER + PLY_XYZ, bytes(24))), "e",
     "is stale"),
    ("points-ply-untied", lambda c: (c / "reconstruction" / "source.json").unlink(), "e",
     "not tied to this capture"),
    ("capture-no-scene", set_json("capture.json", lambda d: d.update(scene=None)), "e",
     "holds no scene"),
]  # fmt: skip
COMMANDS = {"d": ["decode", "{cap}"], "r": ["reconstruct", "{cap}"], "e": ["evaluate", "{cap}"]}

PLYS = [
    ("ply-negative-count", ply(PLY_OK_HEADER.replace("vertex 2", "vertex -5") + PLY_XYZ),
     "negative element count"),
    ("ply-truncated", ply(PLY_OK_HEADER + PLY_XYZ, bytes(5)), "ply"),
    ("ply-not-ply", b"solid cube\n", "ply"),
    ("ply-empty", b"", "ply"),
    ("ply-huge-count", ply(PLY_OK_HEADER.replace("vertex 2", "vertex 99999999999") + PLY_XYZ),
     "ply"),
    ("ply-no-points", ply(PLY_OK_HEADER.replace("vertex 2", "vertex 0") + PLY_XYZ),
     "holds no points"),
    ("ply-binary-header", b"ply\n\xff\xfe\n", "ply"),
    ("ply-mm", ply(PLY_OK_HEADER.replace("ply\n", "ply\ncomment units mm\n") + PLY_XYZ,
                   bytes(24)), "expected metres"),
]  # fmt: skip

IMPORTS = [
    # (id, files (over IMPORT_OK), argv changes, message)
    ("import-empty-folder", {"images": lambda w: (w / "images").mkdir()}, "a folder holding"),
    ("import-count", {"images": import_images(51)}, "52 images (one per sequence frame)"),
    ("import-corrupt", {"images": lambda w: (import_images()(w),
                        (w / "images" / "img7.png").write_bytes(b"junk"))}, "img7.png"),
    ("import-colour", {"images": import_images(channels=3)}, "a colour image"),
    ("import-float", {"images": lambda w: (import_images()(w),
                      cv2.imwrite(str(w / "images" / "img0.tif"), np.zeros((48, 64), np.float32)),
                      (w / "images" / "img0.png").unlink())}, "img0.tif"),
    ("import-size", {"images": import_images(shape=(40, 40))}, "camera"),
    ("import-sequence-list", {"seq.json": "[]"}, "expected a mapping (sequence description)"),
    ("import-sequence-deep", {"seq.json": "[" * 100 + "]" * 100}, "nested at most 64 deep"),
    ("import-calibration-list", {"rig.json": "[]"}, "expected a JSON object"),
    ("import-calibration-zero-baseline", {"rig.json": ZERO_BASELINE}, "baseline is 0 um"),
    ("import-calibration-misspelt", {"rig.json": rig(**{"camera.distortion": [0] * 5})},
     "did you mean 'dist'"),
]  # fmt: skip
IMPORT_ARGS = [
    ("import-bit-depth", ["--bit-depth", "4"], "bit_depth"),
    ("import-bit-depth-text", ["--bit-depth", "x"], "Invalid value for '--bit-depth'"),
    ("import-units", ["--units", "yard"], "'yard' is not one of"),
]


def _cases() -> list:
    cases = [pytest.param({}, argv, message, id=name) for name, argv, message in CLI_OPTIONS]
    for name, content, message in RIG_FILES:
        files = {"bad.json": content}
        cases.append(pytest.param(files, [*CO[:1], "--rig", "{w}/bad.json", "--out", "{out}"],
                                  message, id=f"{name}-capture"))  # fmt: skip
    for name, content, message in RIG_FILES[:8]:  # other readers of the same schema
        files = {"bad.json": content}
        cases.append(pytest.param(files, ["rig", "info", "--rig", "{w}/bad.json"], message,
                                  id=f"{name}-rig-info"))  # fmt: skip
        cases.append(pytest.param(files, [*SC, "--calibration", "{w}/bad.json"], message,
                                  id=f"{name}-scan-calibration"))  # fmt: skip
    for name, content, message in SCENES:
        files = {"s.yaml": content}
        cases.append(pytest.param(files, [*CO, "--scene", "{w}/s.yaml"], message, id=name))
    for name, content, message in SCENES[:4]:
        cases.append(pytest.param({"s.yaml": content}, [*SC, "--scene", "{w}/s.yaml"], message,
                                  id=f"{name}-scan"))  # fmt: skip
    for name, content, message in MESHES:
        cases.append(pytest.param(mesh_scene(content), [*CO, "--scene", "{w}/s.yaml"], message,
                                  id=name))  # fmt: skip
        cases.append(pytest.param(mesh_scene(content),
                                  [*SC, "--scene", "{w}/s.yaml", "--turntable", "4"], message,
                                  id=f"{name}-turntable"))  # fmt: skip
    for name, content, message in SEQUENCES:
        cases.append(pytest.param({"q.yaml": content}, [*CO, "--sequence", "{w}/q.yaml"],
                                  message, id=name))  # fmt: skip
    for name, option, content, message in DEVICE_FILES:
        files = {"d.yaml": content}
        cases.append(pytest.param(files, [*CO, option, "{w}/d.yaml"], message, id=name))
    for name, files, target, message in CALIBRATIONS:
        argv = ["reconstruct", "{cap}", "--calibration", f"{{w}}/{target}"]
        cases.append(pytest.param(files, argv, message, id=name))
    cases.append(pytest.param({"c.json": ZERO_BASELINE}, [*SC, "--calibration", "{w}/c.json"],
                              "baseline is 0 um", id="scan-zero-baseline"))  # fmt: skip
    for name, edit, commands, message in CAPTURE_EDITS:
        for key in commands:
            cases.append(pytest.param(capture_edit(edit), COMMANDS[key], message,
                                      id=f"{name}-{COMMANDS[key][0]}"))  # fmt: skip
    for name, content, message in PLYS:
        cases.append(pytest.param({"p.ply": content}, ["evaluate", "{cap}", "--ply", "{w}/p.ply"],
                                  message, id=name))  # fmt: skip
    for name, files, message in IMPORTS:
        cases.append(pytest.param({**IMPORT_OK, **files}, IMP, message, id=name))
    for name, extra, message in IMPORT_ARGS:
        cases.append(pytest.param(IMPORT_OK, [*IMP, *extra], message, id=name))
    return cases


CASES = _cases()


# --- the capture the decode / reconstruct / evaluate cases start from ---------------------------


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    """A tiny capture (64 x 48 camera, 1 spp) of a mesh before a wall, decoded and
    reconstructed, as the CLI leaves it (its lock file included)."""
    import trimesh

    from virtus.geometry.transforms import Pose
    from virtus.pipeline.scan import reconstruct_capture
    from virtus.render import RenderSettings
    from virtus.scanner import Scanner
    from virtus.scene.model import MeshObject, PlaneObject, Scene

    root = tmp_path_factory.mktemp("template")
    mesh = root / "ball.stl"
    trimesh.creation.icosphere(subdivisions=2, radius=0.1).export(mesh)
    scene = Scene(
        objects=(MeshObject(path=mesh, pose=Pose(np.eye(3), (0.0, 0.0, 1.0))),),
        background=PlaneObject(size_m=(2.0, 2.0), pose=Pose(np.eye(3), (0.0, 0.0, 1.3))),
    )
    scanner = Scanner(rig=Rig.from_dict(_rig_dict()), render=RenderSettings(spp=1))
    directory = root / "cap"
    scanner.capture(scene, rng=0).save(directory)
    reconstruct_capture(directory)
    with directory_lock(directory):
        pass
    return directory


def _snapshot(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _build(work: Path, files: dict) -> None:
    for name, content in files.items():
        if name == "__cap__":
            content(work / "cap")
        elif callable(content):
            content(work)
        elif isinstance(content, bytes):
            (work / name).write_bytes(content)
        else:
            (work / name).write_text(content)


@pytest.mark.parametrize(("files", "argv", "message"), CASES)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(
    files, argv, message, tmp_path, monkeypatch, capsys, request
):
    work = tmp_path / "w"
    work.mkdir()
    uses_capture = any("{cap}" in a for a in argv)
    if uses_capture:
        template = request.getfixturevalue("template")
        shutil.copytree(template, work / "cap")
    (work / "rig.json").write_text(rig())
    _build(work, files)
    monkeypatch.chdir(work)
    values = {"w": str(work), "rig": str(work / "rig.json"), "cap": str(work / "cap"),
              "out": str(work / "out")}  # fmt: skip
    argv = [a.format(**values) for a in argv]
    before = _snapshot(work)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out, err = capsys.readouterr()
    assert exit_info.value.code == 2, (out, err)
    assert "Traceback" not in err and "Traceback" not in out
    lines = err.splitlines()
    assert len(lines) == 1 and err.endswith("\n"), err
    assert lines[0].startswith("virtus: error: "), err
    assert message in lines[0], err
    assert not (work / "out").exists()
    assert _snapshot(work) == before


def test_the_corpus_is_large_and_covers_every_command():
    commands = {case.values[1][0] for case in CASES}
    assert len(CASES) >= 150
    assert {"capture", "scan", "calibrate", "import", "decode", "reconstruct", "evaluate",
            "demo", "ablation", "patterns", "rig"} <= commands  # fmt: skip


# --- hardening: numbers of device files, lenses, distortion, key paths, boards, options -------
# Each case names the culprit (the field, the key path of a non-finite number, the option)
# and is refused before anything is rendered, decoded or written.


def lut(values: list) -> str:
    return f"response_lut: {json.dumps(values)}\n"


RAMP = [i / 255 for i in range(256)]


def nan_in_capture_json(cap: Path) -> None:
    data = json.loads((cap / "capture.json").read_text())
    data["rig"]["camera"]["K"][0][0] = float("nan")
    (cap / "capture.json").write_text(json.dumps(data))  # json writes NaN


def sequence_files(*names: str) -> Callable[[Path], None]:
    """seq.json of the default sequence listing image files, the first ones ``names``."""

    def build(work: Path) -> None:
        from virtus.patterns import default_sequence

        data = default_sequence(912, 1140).to_dict()
        data["files"] = [*names, *(f"img{i}.png" for i in range(len(names), 52))]
        (work / "seq.json").write_text(json.dumps(data))

    return build


def drop_decoded(cap: Path) -> None:
    """No decoded/: a reconstruct would decode (and write decoded/) first."""
    shutil.rmtree(cap / "decoded")


CAPTURES = ["calibrate", "--captures", "{cap}", "--out", "{out}"]
HARDENED_DEVICE_FILES = [
    # (id, option, content, message): every numeric field checked for type, finiteness, range
    ("sensor-percentile-text", "--sensor", "auto_percentile: x\n",
     "auto_percentile: expected a percentile in (0, 100], got 'x'"),
    ("sensor-percentile-zero", "--sensor", "auto_percentile: 0\n", "auto_percentile"),
    ("sensor-exposure-text", "--sensor", "exposure: '5'\n", "exposure: expected"),
    ("sensor-exposure-negative", "--sensor", "exposure: -3\n", "exposure: expected"),
    ("sensor-target-list", "--sensor", "auto_target: [1]\n", "auto_target: expected"),
    ("sensor-qe-bool", "--sensor", "quantum_efficiency: true\n", "quantum_efficiency"),
    ("sensor-gain-text", "--sensor", "system_gain_dn_per_e: high\n", "system_gain_dn_per_e"),
    ("sensor-well-zero", "--sensor", "system_gain_dn_per_e: 1\nsaturation_capacity_e: 0\n",
     "saturation_capacity_e"),
    ("sensor-depth-fraction", "--sensor", "bit_depth: 9.5\n", "bit_depth"),
    ("sensor-seed-negative", "--sensor", "fixed_pattern_seed: -1\n", "fixed_pattern_seed"),
    ("sensor-seed-fraction", "--sensor", "fixed_pattern_seed: 1.5\n", "fixed_pattern_seed"),
    ("sensor-dark-text", "--sensor", "dark_noise_e: lots\n", "dark_noise_e"),
    ("sensor-name-list", "--sensor", "name: [a]\n", "name: expected a non-empty string"),
    ("sensor-prnu-nan", "--sensor", "prnu: .nan\n", "in prnu"),
    ("projector-lut-number", "--projector", "response_lut: 5\n",
     "response_lut: expected a list of 256 non-decreasing numbers"),
    ("projector-lut-strings", "--projector", "response_lut: [a, b]\n", "response_lut: expected"),
    ("projector-lut-256-strings", "--projector", lut(["a"] * 256), "got 'index 0: a'"),
    ("projector-lut-nested", "--projector", lut([[0, 1]] * 256), "response_lut: expected"),
    ("projector-lut-bool", "--projector", lut([*RAMP[:9], True, *RAMP[10:]]), "index 9: True"),
    ("projector-lut-decreasing", "--projector", lut([*RAMP[:9], 0.0, *RAMP[10:]]),
     "non-decreasing"),
    ("projector-lut-end", "--projector", lut([*RAMP[:-1], 0.999]), "the light of level 255"),
    ("projector-lut-inf", "--projector", "response_lut: [.inf]\n", "in response_lut[0]"),
    ("projector-gamma-text", "--projector", "gamma: steep\n", "gamma"),
    ("projector-contrast-huge", "--projector", "contrast_ratio: 1" + "0" * 400 + "\n",
     "in contrast_ratio"),
    ("projector-name-empty", "--projector", "name: ''\n", "name: expected a non-empty string"),
]  # fmt: skip
HARDENED = [
    # (id, files, argv, message)
    ("projector-lens-inside-focal-length", {}, [*CO, "--projector-lens", "0.01,0.001"],
     "focus_distance_m: expected a focus distance beyond the focal length"),
    ("camera-lens-inside-focal-length", {}, [*CO, "--camera-lens", "0.02,0.01"],
     "focus_distance_m"),
    ("rig-dist-7", {"bad.json": rig(**{"camera.dist": [0.1] * 7})},
     [C, "--rig", "{w}/bad.json", "--out", "{out}"],
     "camera.dist: expected 0, 4, 5, 8, 12 or 14 coefficients"),
    ("rig-projector-dist-3", {"bad.json": rig(**{"projector.dist": [0.1, 0.0, 0.0]})},
     [C, "--rig", "{w}/bad.json", "--out", "{out}"], "projector.dist: expected 0, 4, 5, 8"),
    ("rig-dist-14-tilted", {"bad.json": rig(**{"camera.dist": [0.0] * 12 + [0.1, 0.0]})},
     [C, "--rig", "{w}/bad.json", "--out", "{out}"], "camera.dist: expected at most 8"),
    ("rig-nan-names-its-key", {"bad.json": rig().replace('"width": 64', '"width": NaN')},
     ["rig", "info", "--rig", "{w}/bad.json"], "got 'NaN' in camera.width"),
    ("rig-infinity-names-its-key",
     {"bad.json": rig(**{"camera.dist": [0.1, 0.0, 0.0, 0.0, float("inf")]})},
     [C, "--rig", "{w}/bad.json", "--out", "{out}"], "got 'Infinity' in camera.dist[4]"),
    ("scene-nan-names-its-key", {"s.yaml": SPHERE.replace("0.1,", ".nan,")},
     [*CO, "--scene", "{w}/s.yaml"], "got '.nan at line 2' in objects[0].radius_m"),
    ("scene-ambient-inf", {"s.yaml": SPHERE + "ambient: .inf\n"}, [*CO, "--scene", "{w}/s.yaml"],
     "in ambient"),
    ("capture-json-nan-names-its-key", capture_edit(nan_in_capture_json), ["decode", "{cap}"],
     "got 'NaN' in rig.camera.K[0][0]"),
    ("board-spacing-negative", {}, [*CAL, "--board", "circles:4x11,spacing_mm=-40,diameter_mm=20"],
     "board spacing_mm: expected a length > 0 (mm), got '-40'"),
    ("board-spacing-nan", {}, [*CAL, "--board", "circles:4x11,spacing_mm=nan,diameter_mm=20"],
     "board spacing_mm"),
    ("board-diameter-touching", {},
     [*CAL, "--board", "circles:4x11,spacing_mm=40,diameter_mm=30"],
     "board diameter_mm: expected less than spacing_mm / sqrt(2)"),
    ("board-spacing-bare", {}, [*CAL, "--board", "circles:4x11,spacing_mm,diameter_mm=20"],
     "board spacing_mm"),
    ("board-border-negative", {},
     [*CAL, "--board", "circles:4x11,spacing_mm=40,diameter_mm=20,border_mm=-1"],
     "board border_mm"),
    ("board-square-inf", {}, [*CAL, "--board", "checker:6x9,square_mm=inf"], "board square_mm"),
    ("decode-saturation-zero", {}, ["decode", "{cap}", "--saturation-level", "0"],
     "--saturation-level: expected a level in (0, 255]"),
    ("decode-saturation-negative", {}, ["decode", "{cap}", "--saturation-level", "-5"],
     "--saturation-level: expected a level in (0, 255]"),
    ("decode-saturation-above-full-scale", {}, ["decode", "{cap}", "--saturation-level", "300"],
     "--saturation-level"),
    ("decode-saturation-nan", {}, ["decode", "{cap}", "--saturation-level", "nan"],
     "--saturation-level"),
    ("calibrate-captures-poses", {}, [*CAPTURES, "--poses", "random:5"],
     "--poses: expected no rendering option with --captures"),
    ("calibrate-captures-spp", {}, [*CAPTURES, "--spp", "9"], "--spp: expected no rendering"),
    ("calibrate-captures-sensor", {}, [*CAPTURES, "--sensor", "imx174"], "--sensor: expected no"),
    ("calibrate-captures-seed", {}, [*CAPTURES, "--seed", "3"], "--seed: expected no rendering"),
    ("calibrate-captures-rig", {}, [*CAPTURES, "--rig", "{rig}"], "--rig: expected no rendering"),
    ("calibrate-captures-lookup", {}, [*CAPTURES, "--lookup", "psf"], "--lookup: expected no"),
    ("calibrate-captures-bit-depth", {}, [*CAPTURES, "--bit-depth", "12"], "--bit-depth"),
    ("calibrate-points-spp", {}, ["calibrate", "--from-points", "{w}", "--spp", "9"],
     "--spp: expected no rendering option with --from-points"),
    ("calibrate-points-poses", {}, ["calibrate", "--from-points", "{w}", "--poses", "random:5"],
     "--poses: expected no rendering option with --from-points"),
    ("import-sequence-one-image-twice",
     {**IMPORT_OK, "seq.json": sequence_files("img0.png", "img0.png")}, IMP,
     "files: expected a different image for every frame, got \"'img0.png' for frames 0 and 1\""),
    ("import-sequence-one-image-twice-spelt-apart",
     {**IMPORT_OK, "seq.json": sequence_files("img0.png", "img1.png", "./img0.png")}, IMP,
     "'./img0.png' for frames 0 and 2"),
    ("capture-sequence-one-image-twice", {"seq.json": sequence_files("a.png", "a.png")},
     [*CO, "--sequence", "{w}/seq.json"], "'a.png' for frames 0 and 1"),
    # --out is checked before anything is decoded (decoded/ removed: a decode would write it)
    ("reconstruct-out-fifo", {"__cap__": drop_decoded, "o": lambda w: os.mkfifo(w / "o.ply")},
     ["reconstruct", "{cap}", "--out", "{w}/o.ply"], "got 'a FIFO'"),
    ("reconstruct-out-directory",
     {"__cap__": drop_decoded, "o": lambda w: (w / "o.ply").mkdir()},
     ["reconstruct", "{cap}", "--out", "{w}/o.ply"], "got 'a directory'"),
    ("reconstruct-out-symlink",
     {"__cap__": drop_decoded, "o": lambda w: (w / "o.ply").symlink_to(w / "rig.json")},
     ["reconstruct", "{cap}", "--out", "{w}/o.ply"], "got 'a symbolic link to"),
    ("reconstruct-out-device", capture_edit(drop_decoded),
     ["reconstruct", "{cap}", "--out", "/dev/null"], "got 'a character device'"),
    ("reconstruct-out-manifest", capture_edit(drop_decoded),
     ["reconstruct", "{cap}", "--out", "{cap}/capture.json"], "a file name ending in .ply"),
    ("reconstruct-out-under-a-file", capture_edit(drop_decoded),
     ["reconstruct", "{cap}", "--out", "{w}/rig.json/x.ply"], "got 'rig.json is a file'"),
]  # fmt: skip


def _hardened_cases() -> list:
    cases = [
        pytest.param({"d.yaml": content}, [*CO, option, "{w}/d.yaml"], message, id=name)
        for name, option, content, message in HARDENED_DEVICE_FILES
    ]
    cases += [
        pytest.param(files, argv, message, id=name) for name, files, argv, message in HARDENED
    ]
    return cases


@pytest.mark.parametrize(("files", "argv", "message"), _hardened_cases())
def test_hardened_input_names_its_culprit(
    files, argv, message, tmp_path, monkeypatch, capsys, request
):
    test_bad_input_is_one_line_exit_2_and_writes_nothing(
        files, argv, message, tmp_path, monkeypatch, capsys, request
    )


def test_reconstruction_needs_no_ground_truth(template, tmp_path, capsys):
    """A rendered capture whose gt/ was removed (to share its frames) decodes and
    reconstructs; the ground truth itself is then reported missing, not assumed."""
    from virtus.capture import Capture
    from virtus.errors import VirtusError

    cap = tmp_path / "cap"
    shutil.copytree(template, cap)
    shutil.rmtree(cap / "gt")
    shutil.rmtree(cap / "decoded")
    (cap / "points.ply").unlink()
    for argv in (["decode", str(cap)], ["reconstruct", str(cap)]):
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 0, capsys.readouterr().err
    assert (cap / "points.ply").read_bytes().startswith(b"ply\n")
    loaded = Capture.load(cap)
    assert not loaded.has_ground_truth
    with pytest.raises(VirtusError, match="has no ground truth"):
        loaded.ground_truth  # noqa: B018
    # one ground-truth file of several missing: a damaged capture, named when it is read
    shutil.copytree(template / "gt", cap / "gt")
    (cap / "gt" / "depth.npy").unlink()
    damaged = Capture.load(cap)
    with pytest.raises(InputError, match=r"files it lists, got \"missing \['gt/depth\.npy'\]"):
        damaged.ground_truth  # noqa: B018


def test_valid_inputs_next_to_the_hardened_ones_are_accepted(tmp_path):
    from virtus.calib.board import board_from_spec
    from virtus.geometry.optics import ThinLens
    from virtus.sensor import load_projector, load_sensor

    (tmp_path / "s.yaml").write_text("auto_percentile: 95\nexposure: 12\nbit_depth: 12\n")
    assert load_sensor(tmp_path / "s.yaml").exposure == 12.0
    (tmp_path / "p.yaml").write_text(lut(RAMP))
    assert load_projector(tmp_path / "p.yaml").response_lut[-1] == 1.0
    assert ThinLens(0.01, 0.0051).focus_distance_m == 0.0051  # beyond f/0.5's focal length
    dist = [0.1, -0.05, 0.001, 0.002, 0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert Rig.from_dict(_rig_dict(**{"camera.dist": dist})).camera.intrinsics.dist == tuple(
        dist[:8]
    )
    board = board_from_spec("circles:4x11,spacing_mm=40,diameter_mm=20,border_mm=0")
    assert board.center_distance_mm == 40.0
