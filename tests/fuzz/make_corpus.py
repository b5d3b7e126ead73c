"""Write the seed corpus of ``tests/fuzz/corpus`` (valid examples and hand-made malformed ones).

Run ``python -m tests.fuzz.make_corpus`` from the repository root after a format changes; the
files it writes are kept in the repository and replayed by ``tests/fuzz/test_corpus.py``
(regressions the fuzzer found, ``corpus/<reader>/regress-*``, are kept by hand and never
overwritten here). Every seed is small (a few kB at most): the valid ones come from the
project's examples and writers (sequence examples, ``Rig.save_json``,
:func:`virtus.calib.io.save_opencv_yaml`, :func:`virtus.twin.usd.export_usd`, ...), on
tiny devices so that a mutated copy reads in milliseconds.
"""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from pathlib import Path

import cv2
import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[2]
CORPUS = Path(__file__).resolve().parent / "corpus"
ASSETS = Path(__file__).resolve().parent / "assets"


def tiny_rig():
    """A 16 x 12 px camera, a 32 x 24 px projector, distortion on both, a 3-D baseline."""
    from virtus.geometry.devices import Camera, Projector, Rig
    from virtus.geometry.optics import Intrinsics
    from virtus.geometry.transforms import Pose

    cam = Intrinsics(20.5, 20.25, 7.3, 5.7, 16, 12, (-0.11, 0.05, 1e-4, -2e-4, 0.01))
    proj = Intrinsics(30.0, 30.5, 15.1, 11.2, 32, 24, (0.01, -0.02, 3e-4, 1e-4, 0.0))
    return Rig(
        Camera(cam),
        Projector(proj),
        Pose.from_euler("xyz", (5.7, -7.1, 0.4), t=(-0.125, 0.1, 0.013)),
    )


def tiny_sequence():
    from virtus.patterns import PatternSequence

    return PatternSequence.from_dict(
        {
            "width": 32,
            "height": 24,
            "blocks": [
                {"kind": "phase", "direction": "v", "period": 8, "steps": 3},
                {"kind": "gray", "direction": "v", "period": 8, "bits": 3},
                {"kind": "white"},
                {"kind": "black"},
            ],
        }
    )


def _png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    assert ok
    return data.tobytes()


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _fresh(reader: str) -> Path:
    """``corpus/<reader>``, emptied of everything but the ``regress-*`` entries."""
    folder = CORPUS / reader
    folder.mkdir(parents=True, exist_ok=True)
    for entry in folder.iterdir():
        if entry.name.startswith("regress-"):
            continue
        shutil.rmtree(entry) if entry.is_dir() else entry.unlink()
    return folder


def _write(folder: Path, files: dict[str, bytes | str]) -> None:
    for name, data in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data.encode() if isinstance(data, str) else data)


# -- readers --------------------------------------------------------------------------------


def sequences() -> None:
    folder = _fresh("sequence")
    for example in sorted((REPO / "examples" / "sequences").glob("*.yaml")):
        shutil.copy(example, folder / example.name)
    data = tiny_sequence().to_dict()
    _write(folder, {"tiny_frames.json": json.dumps(data, indent=1)})
    _write(
        folder,
        {
            "code_only.yaml": "width: 64\nheight: 32\nblocks:\n"
            "  - {kind: binary, direction: h, bits: 5, bit_order: lsb_first, inverted: true}\n"
            "  - {kind: white}\n  - {kind: black}\n",
            "files.json": json.dumps(
                {
                    "width": 8,
                    "height": 8,
                    "preset": "opencv_graycode",
                    "files": [f"{i:03d}.png" for i in range(14)],
                }  # fmt: skip
            ),
            "bad_anchor.yaml": "a: &a [1, 2]\nwidth: *a\nheight: 8\npreset: opencv_graycode\n",
            "bad_huge_bits.yaml": "width: 8\nheight: 8\nblocks:\n"
            "  - {kind: gray, direction: v, bits: 99999999999999999999}\n",
            "bad_nan_period.json": '{"width": 8, "height": 8, "blocks": [{"kind": "phase", '
            '"direction": "v", "period": NaN, "steps": 3}]}',
            "bad_deep.json": "[" * 5000 + "]" * 5000,
            "bad_frames_type.yaml": "width: 8\nheight: 8\nframes: {kind: white}\n",
            "bad_bom_latin1.yaml": b"\xef\xbb\xbfwidth: \xe9\n",
            "bad_periods_many.yaml": "width: 8\nheight: 8\nblocks:\n"
            "  - {kind: phase, direction: v, steps: 3, periods: ["
            + ", ".join(["4"] * 600)
            + "]}\n",
        },
    )


def calibrations() -> None:
    from virtus.calib.io import save_opencv_yaml, save_paper_txt

    rig = tiny_rig()
    folder = _fresh("calibration")
    rig.save_json(folder / "rig.json")
    _write(folder, {"capture.json": json.dumps({"format": "x", "rig": rig.to_dict()}, indent=1)})
    save_opencv_yaml(rig, folder / "virtus.yaml")
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    cam2proj = rig.proj2cam.inverse()
    for name, suffix in (("stereo.yaml", ".yaml"), ("stereo.xml", ".xml")):
        storage = cv2.FileStorage(f"x{suffix}", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
        storage.write("K1", cam.K)
        storage.write("D1", np.asarray(cam.dist_array).reshape(1, -1))
        storage.write("K2", proj.K)
        storage.write("D2", np.asarray(proj.dist_array).reshape(1, -1))
        storage.write("R", cam2proj.R)
        storage.write("T", cam2proj.t.reshape(3, 1) * 1000)
        storage.write("units", "mm")
        storage.write("image_width", cam.width)
        storage.write("image_height", cam.height)
        storage.write("projector_width", proj.width)
        storage.write("projector_height", proj.height)
        _write(folder, {name: storage.releaseAndGetString()})
    _write(
        folder,
        {
            "moreno.yml": "%YAML:1.0\ncam_K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
            "   data: [20.5, 0., 7.3, 0., 20.25, 5.7, 0., 0., 1.]\n"
            "cam_kc: [0.1, 0.0, 0.0, 0.0, 0.0]\n"
            "proj_K: [[30., 0., 15.1], [0., 30.5, 11.2], [0., 0., 1.]]\nproj_kc: [0, 0, 0, 0, 0]\n"
            "R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nT: [-125.0, 0.0, 13.0]\nunits: mm\n"
            "camera_size: [16, 12]\nprojector_size: [32, 24]\n",
            "bad_negative_cols.yml": "%YAML:1.0\nK1: !!opencv-matrix\n   rows: 3\n   cols: -1\n"
            "   dt: d\n   data: [1, 2, 3]\n",
            "bad_nested_map.yml": "%YAML:1.0\nK1:\n  a:\n    b:\n      c: 1\n",
            "bad_huge_rows.yml": "%YAML:1.0\nK1: !!opencv-matrix\n   rows: 1000000000000\n"
            "   cols: 1000000000000\n   dt: d\n   data: [1]\n",
            "bad_no_units.json": json.dumps(
                {k: v for k, v in rig.to_dict().items() if k != "units"}
            ),
            "bad_rotation.json": json.dumps(
                dict(
                    rig.to_dict(), proj2cam={"R": [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 0]}
                )
            ),
            "bad_xml_entity.xml": '<?xml version="1.0"?>\n<!DOCTYPE a [<!ENTITY x "xxxxxxxx">]>\n'
            "<opencv_storage><K1>&x;&x;</K1></opencv_storage>\n",
        },
    )
    # NumPy .npz stereo files: stereoCalibrate's names, kamino410's procam-calibration names
    cam_dist = np.asarray(cam.dist_array).reshape(1, -1)
    proj_dist = np.asarray(proj.dist_array).reshape(1, -1)
    for name, arrays in {
        "stereo.npz": {
            "K1": cam.K, "D1": cam_dist, "K2": proj.K, "D2": proj_dist, "R": cam2proj.R,
            "T": cam2proj.t.reshape(3, 1) * 1000, "units": np.array("mm"),
            "image_width": np.array(cam.width), "image_height": np.array(cam.height),
        },
        "procam.npz": {
            "cam_int": cam.K, "cam_dist": cam_dist, "proj_int": proj.K, "proj_dist": proj_dist,
            "rotation": cam2proj.R, "translation": cam2proj.t * 1000,
            "img_shape": np.array([cam.height, cam.width]),
        },
    }.items():  # fmt: skip
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        _write(folder, {name: buffer.getvalue()})
    # a mapping file naming the keys of assets/calib.npz (copied beside every case)
    _write(
        folder,
        {
            "mapping.yaml": "file: calib.npz\nkeys:\n  camera_K: cam_mtx\n  camera_dist: cam_dist\n"
            "  projector_K: proj_mtx\n  projector_dist: null\n  R: R\n  T: T\nunits: mm\n"
            "convention: X_proj = R X_cam + T\ncamera_size: [16, 12]\nprojector_size: [32, 24]\n",
        },
    )
    ASSETS.mkdir(exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, cam_mtx=cam.K, cam_dist=cam_dist, proj_mtx=proj.K, R=cam2proj.R,
             T=cam2proj.t * 1000)  # fmt: skip
    _write(ASSETS, {"calib.npz": buffer.getvalue()})
    # the paper code's text folders (a directory per case)
    txt = _fresh("calibration_txt")
    save_paper_txt(rig, txt / "paper")
    _write(
        txt / "paper",
        {"camera_size.txt": "16 12\n", "projector_size.txt": "32, 24\n"},
    )
    _write(
        txt / "commas_and_comments",
        {
            "CamIntrinsicMatrix.txt": "# K\n20.5, 0, 7.3\n0, 20.25, 5.7\n0, 0, 1\n",
            "ProjIntrinsicMatrix.txt": "% K\n30 0 15.1\n0 30.5 11.2\n0 0 1\n",
            "ProjRotationMatrix.txt": "1 0 0\n0 1 0\n0 0 1\n",
            "ProjTranslationVector.txt": "-125\n0\n13\n",
            "CamDistortion.txt": "0.1\t0\t0\t0\t0\n",
            "imageSize.txt": "16 12\n",
            "projector_size.txt": "32 24\n",
        },
    )
    _write(
        txt / "bad_ragged",
        {
            "CamIntrinsicMatrix.txt": "20.5 0 7.3\n0 20.25\n0 0 1\n",
            "ProjIntrinsicMatrix.txt": "30 0 15.1\n0 30.5 11.2\n0 0 1\n",
            "ProjRotationMatrix.txt": "1 0 0\n0 1 0\n0 0 1\n",
            "ProjTranslationVector.txt": "nan\ninf\n1e999\n",
        },
    )
    # pose files of a calibration run (load_npz through the calibration's reader)
    npz = _fresh("pose_npz")
    for name, arrays in {
        "pose.npz": {
            "board2cam": np.eye(4),
            "seed": np.array(7, dtype=np.int64),
            "episode": np.array("e1"),
            "cam_centroids": np.arange(8.0).reshape(4, 2),
            "homographies": np.tile(np.eye(3), (4, 1, 1)),
        },
        "pose_undetected.npz": {
            "board2cam": np.eye(4),
            "seed": np.array(7, dtype=np.int64),
            "episode": np.array("e1"),
        },
    }.items():
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        _write(npz, {name: buffer.getvalue()})
    buffer = io.BytesIO()
    np.savez_compressed(buffer, board2cam=np.eye(4), seed=np.array([7, 8]), episode=np.array(3.5))
    _write(npz, {"bad_seed_shape.npz": buffer.getvalue()})
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("board2cam.npy", _npy(np.eye(4))[:60])
    _write(npz, {"bad_truncated_member.npz": buffer.getvalue()})


def scenes() -> None:
    folder = _fresh("scene")
    shutil.copy(REPO / "examples" / "tabletop.yaml", folder / "tabletop.yaml")
    _write(
        folder,
        {
            "assets.yaml": "objects:\n  - type: mesh\n    path: part.stl\n    scale_to_m: 0.001\n"
            "    pose: {euler_deg: [0, 30, 0], t: [0, 0, 1.1]}\n"
            "  - type: textured_plane\n    size_m: [0.2, 0.1]\n    texture: texture.png\n"
            "    pose: {t: [0, 0, 1.2]}\n"
            "  - type: textured_plane\n    size_m: [0.2, 0.1]\n    texture: texture.npy\n"
            "    pose: {t: [0, 0, 1.25]}\n"
            "  - type: mesh\n    path: part.obj\n    pose: {t: [0, 0, 1.0]}\n"
            "lights:\n  - type: area\n    size_m: [0.5, 0.5]\n    radiance: 2.0\n"
            "    pose: {euler_deg: [-90, 0, 0], t: [0, -0.6, 1.0]}\n"
            "  - type: environment\n    radiance: 0.05\n"
            "background:\n  type: plane\n  size_m: [2, 2]\n"
            "  pose: {R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]], t: [0, 0, 1.3]}\n",
            "bad_alias_bomb.yaml": "a: &a [x, x, x, x, x, x, x, x, x]\n"
            "b: &b [*a, *a, *a, *a, *a, *a]\n"
            "c: &c [*b, *b, *b, *b, *b, *b]\nobjects: [*c, *c, *c, *c]\n",
            "bad_mesh_outside.yaml": "objects:\n  - type: mesh\n"
            "    path: ../../../../etc/passwd.stl\n",
            "bad_python_tag.yaml": "objects: !!python/object/apply:os.system ['true']\n",
            "bad_duplicate_keys.yaml": "ambient: 0.1\nambient: 0.2\n",
        },
    )
    # the files its scenes (and mutations of them) refer to, beside the YAML file
    ASSETS.mkdir(exist_ok=True)
    _write(
        ASSETS,
        {
            "part.stl": _ascii_stl(),
            "part.obj": "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\n"
            "f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n",
            "texture.png": _png(np.arange(48, dtype=np.uint8).reshape(6, 8) * 5),
            "texture.npy": _npy(np.linspace(0, 1, 48).reshape(6, 8)),
            "rig.json": json.dumps(tiny_rig().to_dict()),
        },
    )


def _ascii_stl() -> str:
    facets = []
    tetra = [(0, 0, 0), (10, 0, 0), (0, 10, 0), (0, 0, 10)]
    for a, b, c in ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)):
        lines = "".join(f"      vertex {x} {y} {z}\n" for x, y, z in (tetra[a], tetra[b], tetra[c]))
        facets.append(f"  facet normal 0 0 0\n    outer loop\n{lines}    endloop\n  endfacet\n")
    return "solid part\n" + "".join(facets) + "endsolid part\n"


def meshes() -> None:
    import trimesh

    folder = _fresh("mesh")
    tetra = trimesh.Trimesh(
        np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=np.float64),
        np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
        process=False,
    )
    _write(
        folder,
        {
            "binary.stl": tetra.export(file_type="stl"),
            "ascii.stl": _ascii_stl(),
            "mesh.obj": tetra.export(file_type="obj"),
            "binary.ply": tetra.export(file_type="ply", encoding="binary"),
            "ascii.ply": tetra.export(file_type="ply", encoding="ascii"),
            "bad_stl_count.stl": b"\x00" * 80 + (2**31).to_bytes(4, "little") + b"\x00" * 50,
            "bad_face_index.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999\n",
            "bad_ply_list.ply": "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
            "property float y\nproperty float z\nelement face 1\n"
            "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
            "255 0 1 2\n",
        },
    )


def point_clouds() -> None:
    from virtus.io.ply import write_ply

    folder = _fresh("ply")
    points = np.array([[0.0, 0.1, 1.0], [0.2, -0.1, 1.1], [-0.3, 0.0, 0.9]])
    normals = np.array([[0.0, 0.0, -1.0]] * 3)
    colors = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    scratch = CORPUS / ".scratch"
    scratch.mkdir(exist_ok=True)
    for name, kwargs in {
        "binary.ply": {"normals": normals, "colors": colors},
        "plain.ply": {},
    }.items():
        path = write_ply(scratch / name, points, **kwargs)
        shutil.copy(path, folder / name)
    shutil.rmtree(scratch)
    _write(
        folder,
        {
            "ascii_faces.ply": "ply\nformat ascii 1.0\ncomment units m\nelement vertex 3\n"
            "property float x\nproperty float y\nproperty float z\nelement face 1\n"
            "property list uchar int vertex_indices\nend_header\n0 0 1\n1 0 1\n0 1 1\n3 0 1 2\n",
            "big_endian.ply": b"ply\nformat binary_big_endian 1.0\nelement vertex 2\n"
            b"property double x\nproperty double y\nproperty double z\nend_header\n"
            + np.array([[0, 0, 1], [1, 1, 2]], dtype=">f8").tobytes(),
            "bad_huge_count.ply": "ply\nformat binary_little_endian 1.0\n"
            "element vertex 99999999999999999999\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n",
            "bad_list_before.ply": b"ply\nformat binary_little_endian 1.0\nelement face 1\n"
            b"property list uint int vertex_indices\nelement vertex 1\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n\xff\xff\xff\x7f",
        },
    )


def arrays() -> None:
    folder = _fresh("npy")
    _write(
        folder,
        {
            "float64.npy": _npy(np.linspace(0, 1, 12).reshape(3, 4)),
            "fortran.npy": _npy(np.asfortranarray(np.arange(6, dtype=np.float32).reshape(2, 3))),
            "bool.npy": _npy(np.array([[True, False], [False, True]])),
            "uint16_be.npy": _npy(np.arange(4, dtype=">u2")),
            "scalar.npy": _npy(np.array(3.5)),
        },
    )
    buffer = io.BytesIO()
    np.save(buffer, np.array([None, 1], dtype=object), allow_pickle=True)
    _write(folder, {"bad_pickle.npy": buffer.getvalue()})
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 1000000000000), }"
    header = header.ljust(117) + "\n"
    _write(
        folder,
        {
            "bad_huge_shape.npy": b"\x93NUMPY\x01\x00"
            + len(header).to_bytes(2, "little")
            + header.encode()
        },
    )
    header = "{'descr': [('a', '<i4')], 'fortran_order': False, 'shape': (2,), }".ljust(117) + "\n"
    _write(
        folder,
        {
            "bad_structured.npy": b"\x93NUMPY\x01\x00"
            + len(header).to_bytes(2, "little")
            + header.encode()
            + b"\x00" * 8
        },
    )


def images() -> None:
    folder = _fresh("image")
    grey8 = (np.arange(48, dtype=np.uint8).reshape(6, 8) * 5).astype(np.uint8)
    grey16 = grey8.astype(np.uint16) * 257
    for name, image in {
        "grey8.png": grey8,
        "grey16.png": grey16,
        "grey8.bmp": grey8,
        "grey8.tif": grey8,
        "grey16.tif": grey16,
        "colour_equal.png": np.dstack([grey8] * 3),
        "bad_colour.png": np.dstack([grey8, grey8[::-1], grey8]),
    }.items():
        ok, data = cv2.imencode(Path(name).suffix, image)
        assert ok
        _write(folder, {name: data.tobytes()})
    png = _png(grey8)
    # IHDR claiming 2**31-1 x 2**31-1 (CRC left stale)
    huge = png[:16] + (2**31 - 1).to_bytes(4, "big") * 2 + png[24:]
    _write(folder, {"bad_huge_ihdr.png": huge, "bad_truncated.png": png[: len(png) // 2]})


def textures() -> None:
    folder = _fresh("texture")
    grey8 = (np.arange(48, dtype=np.uint8).reshape(6, 8) * 5).astype(np.uint8)
    _write(
        folder,
        {
            "grey8.png": _png(grey8),
            "grey16.png": _png(grey8.astype(np.uint16) * 257),
            "colour.png": _png(np.dstack([grey8, grey8[::-1], grey8])),
            "albedo.npy": _npy(np.linspace(0, 1, 48).reshape(6, 8)),
            "bad_range.npy": _npy(np.linspace(0, 2, 48).reshape(6, 8)),
            "float.tif": cv2.imencode(
                ".tif", np.linspace(0, 1, 48, dtype=np.float32).reshape(6, 8)
            )[1].tobytes(),
        },
    )


def devices() -> None:
    from virtus.sensor.camera import SENSOR_PRESETS
    from virtus.sensor.projector import PROJECTOR_PRESETS

    folder = _fresh("sensor")
    for name in ("imx174", "webcam"):
        data = SENSOR_PRESETS[name].to_dict()
        data.pop("name", None)
        _write(folder, {f"{name}.yaml": yaml.safe_dump(data), f"{name}.json": json.dumps(data)})
    _write(
        folder,
        {"bad_bits.yaml": "bit_depth: 13\n", "bad_gain.yaml": "system_gain_dn_per_e: .nan\n"},
    )
    folder = _fresh("projector")
    for name, model in PROJECTOR_PRESETS.items():
        data = model.to_dict()
        data.pop("name", None)
        _write(folder, {f"{name}.yaml": yaml.safe_dump(data), f"{name}.json": json.dumps(data)})
    _write(folder, {"bad_gamma.yaml": "gamma: -1e400\n", "bad_pixel.yaml": "pixel: [psf]\n"})


def captures() -> None:
    from virtus.capture.capture import Capture

    folder = _fresh("capture")
    rig, sequence = tiny_rig(), tiny_sequence()
    rng = np.random.default_rng(0)
    height, width = rig.camera.intrinsics.height, rig.camera.intrinsics.width
    frames = rng.integers(0, 256, size=(len(sequence), height, width), dtype=np.uint8)
    Capture(sequence=sequence, rig=rig, frame_data=frames, provenance={"source": "fuzz"}).save(
        folder / "imported"
    )
    from virtus.capture.groundtruth import GroundTruth

    depth = np.full((height, width), 1.0)
    points = np.dstack([np.zeros((height, width)), np.zeros((height, width)), depth])
    normals = np.dstack([np.zeros((height, width))] * 2 + [-np.ones((height, width))])
    gt = GroundTruth.from_arrays(
        {
            "depth": depth,
            "points": points,
            "normals": normals,
            "proj_uv": np.zeros((height, width, 2)),
            "mask_hit": np.ones((height, width), bool),
            "mask_shadow": np.zeros((height, width), bool),
            "mask_outside": np.zeros((height, width), bool),
        }
    )
    frames16 = (frames.astype(np.uint16) * 16).astype(np.uint16)
    Capture(
        sequence=sequence, rig=rig, frame_data=frames16, bit_depth=12, seed=3, gt_data=gt,
        provenance={"source": "fuzz"},
    ).save(folder / "with_gt")  # fmt: skip


def usd_stages() -> None:
    from virtus.geometry.transforms import Pose
    from virtus.scene.model import BoxObject, PlaneObject, Scene, SphereObject
    from virtus.twin.usd import export_usd

    folder = _fresh("usd")
    scene = Scene(
        objects=(
            SphereObject(0.05, (0.0, 0.0, 1.0)),
            BoxObject((0.05, 0.05, 0.05), Pose(np.eye(3), (0.1, 0, 1))),
        ),
        background=PlaneObject((2.0, 2.0), Pose(np.eye(3), (0.0, 0.0, 1.3))),
    )
    export_usd(folder / "scene.usda", scene=scene, rig=tiny_rig(), meters_per_unit=0.01)
    export_usd(folder / "rig_only.usda", rig=tiny_rig())
    for extra in folder.iterdir():  # textures and meshes written beside: not seeds
        if extra.suffix != ".usda":
            shutil.rmtree(extra) if extra.is_dir() else extra.unlink()
    _write(
        folder,
        {
            "bad_sublayer.usda": "#usda 1.0\n(\n    subLayers = [@missing.usda@]\n)\n",
            "bad_mpu.usda": "#usda 1.0\n(\n    metersPerUnit = -1\n)\n"
            'def Sphere "s"\n{\n    double radius = 1\n}\n',
            "bad_reference.usda": '#usda 1.0\ndef "a" (\n'
            "    references = @nothing.usda@</x>\n)\n{\n}\n",
            "bad_camera.usda": '#usda 1.0\ndef Camera "cam"\n{\n    float focalLength = -5\n'
            "    float horizontalAperture = 0\n}\n",
        },
    )


def dataset_configs() -> None:
    folder = _fresh("dataset_config")
    for example in sorted((REPO / "examples" / "datasets").glob("*.yaml")):
        shutil.copy(example, folder / example.name)
    _write(
        folder,
        {
            "tiny.yaml": yaml.safe_dump(
                {
                    "mode": "training",
                    "seed": 11,
                    "num_samples": 4,
                    "rig": {"file": "rig.json"},
                    "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]},
                    "objects": {
                        "sources": [{"type": "sphere", "radius_m": [0.04, 0.08], "instances": 12}]
                    },
                    "storage": {"shard_samples": 2},
                }  # fmt: skip
            ),
            "bad_splits.yaml": "mode: training\nseed: 0\nnum_samples: 3\nsplits: {train: .nan}\n",
        },
    )


def main() -> None:
    sequences()
    calibrations()
    scenes()
    meshes()
    point_clouds()
    arrays()
    images()
    textures()
    devices()
    captures()
    usd_stages()
    dataset_configs()
    total = sum(1 for p in CORPUS.rglob("*") if p.is_file())
    size = sum(p.stat().st_size for p in CORPUS.rglob("*") if p.is_file())
    print(f"{total} files, {size / 1024:.0f} kB in {CORPUS}")


if __name__ == "__main__":
    main()
