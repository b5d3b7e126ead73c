"""Binary PLY writer and reader."""

from pathlib import Path

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.io.ply import PlyError, read_ply, write_ply


def test_round_trip_float64_with_normals_and_colours(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    colors = rng.integers(0, 256, size=(500, 3))
    path = write_ply(tmp_path / "a" / "cloud.ply", points, normals=normals, colors=colors,
                     dtype=np.float64, frame="camera", comments=("scene sphere",))  # fmt: skip
    header = path.read_bytes().split(b"end_header")[0].decode()
    assert "format binary_little_endian 1.0" in header
    assert "comment units m" in header
    assert "property double x" in header and "property uchar red" in header
    cloud = read_ply(path)
    assert np.array_equal(cloud.points, points)
    assert np.array_equal(cloud.normals, normals.astype(np.float32).astype(np.float64))
    assert np.array_equal(cloud.colors, colors.astype(np.uint8))
    assert cloud.units == "m" and cloud.frame == "camera"
    assert "scene sphere" in cloud.comments


def test_float32_points_only(tmp_path: Path) -> None:
    points = np.array([[0.1, -0.2, 1.0], [0.0, 0.0, 0.5]])
    cloud = read_ply(write_ply(tmp_path / "p.ply", points))
    assert cloud.normals is None and cloud.colors is None
    assert np.array_equal(cloud.points, points.astype(np.float32).astype(np.float64))
    assert (tmp_path / "p.ply").stat().st_size == len(
        (tmp_path / "p.ply").read_bytes().split(b"end_header\n")[0]
    ) + len(b"end_header\n") + 2 * 12


def test_reads_ascii_and_big_endian_with_faces(tmp_path: Path) -> None:
    ascii_ply = tmp_path / "ascii.ply"
    ascii_ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    assert np.array_equal(read_ply(ascii_ply).points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert read_ply(ascii_ply).units is None
    big = tmp_path / "big.ply"
    body = np.array([[1.5, 2.5, 3.5]], dtype=">f8").tobytes()
    header = ("ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\n"
              "property double y\nproperty double z\nend_header\n")  # fmt: skip
    big.write_bytes(header.encode() + body)
    assert np.array_equal(read_ply(big).points, [[1.5, 2.5, 3.5]])


def test_empty_cloud_round_trips(tmp_path: Path) -> None:
    cloud = read_ply(write_ply(tmp_path / "e.ply", np.zeros((0, 3))))
    assert len(cloud) == 0
    ascii_ply = tmp_path / "e_ascii.ply"
    ascii_ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n"
    )
    assert read_ply(ascii_ply).points.shape == (0, 3)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty file"),
        (b"solid cube\nendsolid\n", "not a PLY"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\n", "end_header"),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n\x00\x00",
            "truncated",
        ),
        (b"ply\nformat binary_little_endian 1.0\nelement face 0\nend_header\n", "no vertex"),
        (b"ply\nformat weird 1.0\nelement vertex 0\nend_header\n", "unknown PLY format"),
    ],
    ids=["empty", "stl", "no-end", "truncated", "no-vertex", "format"],
)
def test_bad_files_raise_ply_error(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(PlyError, match=message):
        read_ply(path)


def test_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="points"):
        write_ply(tmp_path / "x.ply", [[0.0, np.nan, 1.0]])
    with pytest.raises(InputError, match="colors"):
        write_ply(tmp_path / "x.ply", np.zeros((1, 3)), colors=[[0, 0, 256]])
    with pytest.raises(InputError, match="normals"):
        write_ply(tmp_path / "x.ply", np.zeros((2, 3)), normals=np.zeros((1, 3)))
    with pytest.raises(InputError, match="dtype"):
        write_ply(tmp_path / "x.ply", np.zeros((1, 3)), dtype=np.int32)
    with pytest.raises(InputError, match=r"^point cloud: expected an existing PLY file"):
        read_ply(tmp_path / "missing.ply")


_XYZ = b"property float x\nproperty float y\nproperty float z\n"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"ply\nformat binary_little_endian 1.0\nelement vertex -5\n" + _XYZ + b"end_header\n",
         r"negative element count in 'element vertex -5'"),
        (b"ply\nformat ascii 1.0\nelement vertex -1\n" + _XYZ + b"end_header\n",
         "negative element count"),
        # 10^15 vertices announced over 12 bytes: refused before allocating or walking them
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000\n" + _XYZ
         + b"end_header\n" + bytes(12),
         r"truncated \(1000000000000000 vertex records of at least 12 bytes, 12 bytes left\)"),
        # a face element before the vertices announcing more records than bytes left
        (b"ply\nformat binary_little_endian 1.0\nelement face 1000000000000\n"
         b"property list uchar int vertex_indices\nelement vertex 1\n" + _XYZ
         + b"end_header\n" + bytes(12),
         r"truncated \(1000000000000 face records"),
        # negative list lengths (signed count type) would walk backwards forever
        (b"ply\nformat binary_little_endian 1.0\nelement face 3\n"
         b"property list char uchar vertex_indices\nelement vertex 1\n" + _XYZ
         + b"end_header\n" + b"\xff" * 3 + bytes(12),
         r"negative list length in property 'vertex_indices'"),
        (b"ply\nformat ascii 1.0\nelement vertex 1000000\n" + _XYZ + b"end_header\n0 0 0\n",
         r"truncated"),
        (b"ply\nformat ascii 1.0\ncomment caf\xe9\nelement vertex 0\n" + _XYZ
         + b"end_header\n", r"header is not UTF-8 text"),
        (b"ply\nformat ascii 1.0\nelement vertex 2\n" + _XYZ + b"end_header\n0 0 1\nnan 0 1\n",
         r"1 of 2 points have non-finite coordinates \(first: vertex 1\)"),
    ],
    ids=["negative", "negative-ascii", "absurd", "absurd-faces", "negative-list", "ascii-short",
         "non-utf8", "nan"],
)  # fmt: skip
def test_garbage_headers_and_bodies_are_refused(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(PlyError, match=message) as error:
        read_ply(path)
    assert isinstance(error.value, ValueError) and "\n" not in str(error.value)


def test_utf8_comments_are_read_and_size_is_bounded(tmp_path: Path, monkeypatch) -> None:
    with pytest.raises(InputError, match="comments: expected single-line ASCII strings"):
        write_ply(tmp_path / "c.ply", np.zeros((4, 3)), comments=("scanned at 20 °C",))
    # other writers put UTF-8 in comments: read them
    path = write_ply(tmp_path / "c.ply", np.zeros((4, 3)), comments=("scanned at 20 C",))
    path.write_bytes(path.read_bytes().replace(b"20 C", "20 °C".encode()))
    assert "scanned at 20 °C" in read_ply(path).comments
    monkeypatch.setattr("virtus.io.ply.MAX_CLOUD_BYTES", 100)
    with pytest.raises(InputError, match=r"^point cloud .*c\.ply: expected a PLY file of at most"):
        read_ply(path)
