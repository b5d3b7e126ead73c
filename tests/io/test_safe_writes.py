"""Writes that never harm what they replace (virtus.io.safewrite, runs.atomic_write,
jsonio.write_json): only a missing path or a regular file is replaced -- a device, FIFO,
socket, directory or symbolic link in its place is refused in one line naming it, before
anything is written -- and a full disk is named as such, with the path."""

from __future__ import annotations

import builtins
import errno
import json
import os
import socket
import stat
from pathlib import Path

import numpy as np
import pytest

from virtus.cli import main
from virtus.errors import InputError
from virtus.io import images as images_module
from virtus.io.jsonio import write_json
from virtus.io.runs import TMP_DIR, atomic_write, atomic_write_files

DEV_FULL = Path("/dev/full")


def tiny_rig():
    from virtus.geometry.devices import Camera, Rig, default_rig
    from virtus.geometry.optics import Intrinsics

    rig = default_rig()
    cam = rig.camera.intrinsics
    camera = Camera(Intrinsics(cam.fx / 15, cam.fy / 15, 31.5, 23.5, 64, 48))
    return Rig(camera, rig.projector, rig.proj2cam)


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory) -> Path:
    """A tiny rendered capture (64 x 48 camera, 1 spp, a sphere before a wall)."""
    from virtus.geometry.transforms import Pose
    from virtus.render import RenderSettings
    from virtus.scanner import Scanner
    from virtus.scene.model import PlaneObject, Scene, SphereObject

    scene = Scene(
        objects=(SphereObject(0.1, (0.0, 0.0, 1.0)),),
        background=PlaneObject((2.0, 2.0), Pose(np.eye(3), (0.0, 0.0, 1.3))),
    )
    directory = tmp_path_factory.mktemp("capture") / "cap"
    Scanner(rig=tiny_rig(), render=RenderSettings(spp=1)).capture(scene, rng=0).save(directory)
    return directory


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in argv])
    return exit_info.value.code, capsys.readouterr().err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# -- the writer ------------------------------------------------------------------------------------


def _specials(folder: Path) -> dict[str, tuple[Path, str]]:
    """Things that are not regular files, by name: (path, the kind the message names)."""
    outside = folder.parent / f"{folder.name}-outside.txt"
    outside.write_text("precious")
    inside = folder / "inside.txt"
    inside.write_text("also precious")
    made = {
        "fifo": (folder / "fifo", "a FIFO"),
        "directory": (folder / "dir", "a directory"),
        "link-outside": (folder / "out-link", "a symbolic link to"),
        "link-inside": (folder / "in-link", "a symbolic link to"),
        "dangling-link": (folder / "dangling", "a symbolic link to"),
        "socket": (folder / "sock", "a socket"),
    }
    os.mkfifo(made["fifo"][0])
    made["directory"][0].mkdir()
    made["link-outside"][0].symlink_to(outside)
    made["link-inside"][0].symlink_to(inside)
    made["dangling-link"][0].symlink_to(folder.parent / "nowhere" / "file")
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(made["socket"][0]))
    server.close()
    if stat.S_ISCHR(os.lstat(DEV_FULL).st_mode):
        made["char-device"] = (DEV_FULL, "a character device")
    return made


def _state(path: Path) -> tuple:
    """What must not change: the entry's kind and device, and a link's target's bytes."""
    info = os.lstat(path)
    target = path.resolve()
    content = target.read_bytes() if stat.S_ISLNK(info.st_mode) and target.is_file() else None
    return info.st_mode, info.st_rdev, info.st_ino, content


def test_only_regular_files_are_replaced(tmp_path) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    for name, (path, kind) in _specials(folder).items():
        before = _state(path)
        calls: list[object] = []

        def staged(tmp: Path, calls: list[object] = calls) -> None:
            calls.append(tmp.write_bytes(b"new"))

        for write in (
            lambda p: atomic_write(p, staged),
            lambda p: atomic_write_files(p.parent, [p.name], lambda s: staged(s / p.name)),
            lambda p: write_json(p, {"a": 1}),
        ):
            with pytest.raises(InputError) as error:
                write(path)
            message = str(error.value)
            assert "\n" not in message and str(path) in message and kind in message, name
            assert message.startswith(f"output file {path}: expected a regular file or a new path")
        assert not calls, f"{name}: the writer ran"
        assert _state(path) == before, f"{name} changed"
        assert not (path.parent / TMP_DIR).exists(), f"{name}: a staging directory was made"
    # a regular file is replaced; a new path is written
    (folder / "plain.txt").write_text("old")
    atomic_write(folder / "plain.txt", lambda tmp: tmp.write_text("new"))
    write_json(folder / "new.json", {"a": 1})
    assert (folder / "plain.txt").read_text() == "new"
    assert json.loads((folder / "new.json").read_text()) == {"a": 1}
    assert (tmp_path / "out-outside.txt").read_text() == "precious"
    assert (folder / "inside.txt").read_text() == "also precious"


def test_a_linked_staging_directory_or_staged_file_is_never_followed(tmp_path) -> None:
    folder, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    folder.mkdir()
    elsewhere.mkdir()
    (elsewhere / "a.txt").write_text("precious")
    (folder / TMP_DIR).symlink_to(elsewhere)
    with pytest.raises(InputError, match=r"staging directory .*: .*a symbolic link to"):
        atomic_write(folder / "a.txt", lambda tmp: tmp.write_text("new"))
    assert (elsewhere / "a.txt").read_text() == "precious"
    assert (folder / TMP_DIR).is_symlink()
    # a link a killed writer left under a staged name is removed, not written through
    (folder / TMP_DIR).unlink()
    (folder / TMP_DIR).mkdir()
    (folder / TMP_DIR / "a.txt").symlink_to(elsewhere / "a.txt")
    atomic_write(folder / "a.txt", lambda tmp: tmp.write_text("new"))
    assert (folder / "a.txt").read_text() == "new" and not (folder / "a.txt").is_symlink()
    assert (elsewhere / "a.txt").read_text() == "precious"


# -- virtus reconstruct --out ----------------------------------------------------------------------


def test_reconstruct_out_dev_full_is_refused_and_the_device_untouched(capture_dir, capsys):
    info = os.lstat(DEV_FULL) if DEV_FULL.exists() else None
    if info is None or not stat.S_ISCHR(info.st_mode):
        pytest.skip("no /dev/full character device here")
    code, err = run_cli(["reconstruct", capture_dir, "--out", DEV_FULL], capsys)
    line = one_line(err)
    assert code == 2
    assert "/dev/full" in line and "a character device" in line
    after = os.lstat(DEV_FULL)
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == info.st_rdev
    assert after.st_ino == info.st_ino
    assert not (DEV_FULL.parent / TMP_DIR).exists()


@pytest.mark.parametrize("kind", ["fifo", "directory", "link-outside"])
def test_reconstruct_out_refuses_what_is_no_regular_file(capture_dir, tmp_path, capsys, kind):
    outside = tmp_path / "outside.ply"
    outside.write_text("someone else's cloud")
    target = tmp_path / "target.ply"
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    else:
        target.symlink_to(outside)
    before = _state(target)
    code, err = run_cli(["reconstruct", capture_dir, "--out", target], capsys)
    line = one_line(err)
    assert code == 2 and str(target) in line
    kinds = {"fifo": "a FIFO", "directory": "a directory", "link-outside": "a symbolic link to"}
    assert kinds[kind] in line
    assert _state(target) == before
    assert outside.read_text() == "someone else's cloud"


def test_reconstruct_replaces_a_regular_file_of_its_run(capture_dir, capsys) -> None:
    target = capture_dir / "again.ply"
    target.write_text("an older cloud")
    code, err = run_cli(["reconstruct", capture_dir, "--out", target], capsys)
    assert code == 0, err
    assert target.read_bytes().startswith(b"ply\n")
    code, err = run_cli(["reconstruct", capture_dir], capsys)  # its own points.ply, again
    assert code == 0, err
    assert (capture_dir / "points.ply").read_bytes().startswith(b"ply\n")


# -- a full disk -----------------------------------------------------------------------------------


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_names_the_file_and_keeps_the_old_one(tmp_path) -> None:
    target = tmp_path / "a.json"
    target.write_text("old")
    with pytest.raises(OSError) as error:
        atomic_write(target, _no_space)
    assert error.value.errno == errno.ENOSPC and error.value.filename == str(target)
    assert target.read_text() == "old" and not (tmp_path / TMP_DIR).exists()


def _frames_to_dev_full(monkeypatch) -> None:
    """Frame files opened for writing go to /dev/full: a real ENOSPC from the kernel."""
    if not DEV_FULL.exists():
        pytest.skip("no /dev/full here")

    def full_open(path, mode="r", *args, **kwargs):
        if "w" in mode:
            return builtins.open(DEV_FULL, mode, *args, **kwargs)
        return builtins.open(path, mode, *args, **kwargs)

    monkeypatch.setattr(images_module, "open", full_open, raising=False)


def test_capture_on_a_full_disk_says_so_in_one_line(tmp_path, capsys, monkeypatch) -> None:
    _frames_to_dev_full(monkeypatch)
    rig = tiny_rig().save_json(tmp_path / "rig.json")
    out = tmp_path / "out"
    code, err = run_cli(["capture", "--rig", rig, "--spp", "1", "--out", out], capsys)
    line = one_line(err)
    assert code == 2
    assert "no space left on device" in line and str(out / "frames") in line, line
    assert TMP_DIR not in line  # the user's path, not the staging copy
    assert not list(out.glob("frames/*.png"))


def test_import_on_a_full_disk_says_so_in_one_line(
    capture_dir, tmp_path, capsys, monkeypatch
) -> None:
    from virtus.patterns import default_sequence

    rig = tiny_rig().save_json(tmp_path / "rig.json")
    (tmp_path / "seq.json").write_text(json.dumps(default_sequence(912, 1140).to_dict()))
    _frames_to_dev_full(monkeypatch)
    out = tmp_path / "out"
    argv = ["import", capture_dir / "frames", "--sequence", tmp_path / "seq.json",
            "--calibration", rig, "--out", out]  # fmt: skip
    code, err = run_cli(argv, capsys)
    line = one_line(err)
    assert code == 2
    assert "no space left on device" in line and str(out / "frames") in line, line


def test_reconstruct_on_a_full_disk_names_the_cloud(capture_dir, tmp_path, capsys, monkeypatch):
    from virtus.capture import scandir

    monkeypatch.setattr(scandir, "write_ply", _no_space)
    target = tmp_path / "cloud.ply"
    code, err = run_cli(["reconstruct", capture_dir, "--out", target], capsys)
    line = one_line(err)
    assert code == 2
    assert line == (
        f"virtus: error: no space left on device writing {target}; free some space or write "
        "elsewhere"
    )
    assert not target.exists()
