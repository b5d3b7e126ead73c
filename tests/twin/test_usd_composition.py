"""USD stages whose composition fails, or whose units are impossible, are refused with one
line naming what is missing (no USD warning besides it, nothing written), and the mesh
files of a scene are checked before ``export-usd`` writes anything; the same stages made
whole are read."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
import yaml

from virtus.cli import main
from virtus.errors import InputError

pxr = pytest.importorskip("pxr")

from virtus.twin.usd import export_usd, read_usd  # noqa: E402

SPHERE = 'def Sphere "{name}"\n{{\n    double radius = 0.1\n    double3 xformOp:translate = (0, 0, {z})\n    uniform token[] xformOpOrder = ["xformOp:translate"]\n}}\n'  # noqa: E501


def layer(path: Path, body: str, metadata: str = "") -> Path:
    header = f"#usda 1.0\n(\n{metadata}\n)\n" if metadata else "#usda 1.0\n"
    path.write_text(header + body)
    return path


@pytest.fixture
def parts(tmp_path) -> Path:
    """Layers a stage may compose: a sublayer, a referenced and a payload file."""
    layer(tmp_path / "sub.usda", SPHERE.format(name="FromSublayer", z=1.0))
    for name in ("ref", "payload"):
        layer(tmp_path / f"{name}.usda", SPHERE.format(name="Ball", z=1.5), 'defaultPrim = "Ball"')
    return tmp_path


def stage(folder: Path, sublayer="sub.usda", reference="ref.usda", payload="payload.usda", mpu="1"):
    body = (
        SPHERE.format(name="Root", z=2.0)
        + f'def Sphere "Referenced" (\n    references = @./{reference}@\n)\n{{\n}}\n'
        + f'def Sphere "Loaded" (\n    payload = @./{payload}@\n)\n{{\n}}\n'
    )
    metadata = f"    subLayers = [@./{sublayer}@]\n    metersPerUnit = {mpu}"
    return layer(folder / "stage.usda", body, metadata)


def export_usd_cli(scene: Path, out: Path, capfd) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(["export-usd", "--scene", str(scene), "--out", str(out)])
    stdout, stderr = capfd.readouterr()
    return exit_info.value.code, stdout, stderr


def test_a_whole_stage_is_read_with_every_layer(parts, tmp_path, capfd):
    contents = read_usd(stage(parts))
    assert contents.meters_per_unit == 1.0
    assert len(contents.scene.objects) == 4  # root, sublayer, reference and payload spheres
    code, stdout, stderr = export_usd_cli(stage(parts), tmp_path / "out" / "s.usda", capfd)
    assert code == 0 and (tmp_path / "out" / "s.usda").is_file(), stderr


@pytest.mark.parametrize(
    ("arc", "missing"),
    [("sublayer", "gone_sub.usda"), ("reference", "gone_ref.usda"), ("payload", "gone.usda")],
)
def test_a_missing_sublayer_reference_or_payload_is_one_line(parts, tmp_path, capfd, arc, missing):
    path = stage(parts, **{arc: missing})
    with pytest.raises(InputError, match=rf"{arc} @[^@]*{missing}@ .*got 'not found'"):
        read_usd(path)
    capfd.readouterr()
    out = tmp_path / "out"
    code, stdout, stderr = export_usd_cli(path, out / "s.usda", capfd)
    assert code == 2
    # one line on the process's stderr: USD's own warning is not printed besides it
    assert stderr.count("\n") == 1 and stderr.startswith("virtus: error: stage"), stderr
    assert missing in stderr and arc in stderr
    assert not out.exists()


@pytest.mark.parametrize("mpu", ["0", "-0.01", "nan"])
def test_an_impossible_meters_per_unit_is_named(parts, tmp_path, capfd, mpu):
    path = stage(parts, mpu=mpu)
    with pytest.raises(InputError, match="metersPerUnit: expected a positive number"):
        read_usd(path)
    code, _, stderr = export_usd_cli(path, tmp_path / "out" / "s.usda", capfd)
    assert code == 2 and stderr.count("\n") == 1 and "metersPerUnit" in stderr, stderr
    assert "radius" not in stderr and not (tmp_path / "out").exists()


def test_export_usd_refuses_a_truncated_stl_before_writing(tmp_path, capfd):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    good, bad = tmp_path / "good.stl", tmp_path / "bad.stl"
    mesh.export(good)
    bad.write_bytes(good.read_bytes()[:-25])
    for name, path in (("good", good), ("bad", bad)):
        scene = {"objects": [{"type": "mesh", "path": str(path), "pose": {"t": [0, 0, 1]}}]}
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(scene))
    out = tmp_path / "out"
    code, _, stderr = export_usd_cli(tmp_path / "bad.yaml", out / "s.usda", capfd)
    assert code == 2 and stderr.count("\n") == 1 and str(bad) in stderr, stderr
    assert "84 + 50 x 320" in stderr and not out.exists()
    code, _, stderr = export_usd_cli(tmp_path / "good.yaml", out / "s.usda", capfd)
    assert code == 0 and (out / "s.usda").is_file(), stderr
    # a file cut after its scene was loaded: still refused before anything is written
    from virtus.scene.model import MeshObject, Scene

    obj = MeshObject(path=good, pose={"t": [0, 0, 1]})
    good.write_bytes(good.read_bytes()[:-50])
    with pytest.raises(InputError, match=r"mesh .*good\.stl"):
        export_usd(tmp_path / "late" / "s.usda", scene=Scene(objects=(obj,)))
    assert not (tmp_path / "late").exists()
