"""``virtus calibrate`` owns its output directory: killed and resumed runs end byte for byte
where an uninterrupted run ends, without rendering a finished pose again; concurrent runs
are refused; identical runs are identical; degenerate pose sets are refused.

The command runs in subprocesses on a small scanner (the paper's rig at a quarter of its
resolution, 1 spp, 4x7 board, 6 random poses: about 3 s a run on 2 cores).
"""

from __future__ import annotations

import hashlib
import json
import re
import signal
import subprocess
import sys
import time
import warnings
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.calib import detect
from virtus.calib.poses import BoardPose
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.transforms import Pose
from virtus.pipeline.calibrate import calibrate_rig, recalibrate
from virtus.render import RenderSettings
from virtus.scanner import Scanner

pytestmark = pytest.mark.slow

#: The files that must be identical between identical runs (everything but run.json's log
#: and timing.json).
COMPARED = ("calibration.json", "calibration.yaml", "episode.json", "paper_txt/*.txt", "poses/*")
N_POSES = 6
#: Poll interval (s) while watching a run's pose files appear (a pose takes ~0.2 s).
POLL_S = 0.002


def quarter_rig() -> Rig:
    """The paper's rig at a quarter of its resolution (240 x 240 camera, 228 x 285 projector):
    both devices are resampled (unlike ``tests.support.small_rig``), so their
    pixels keep the paper's footprint ratio on the board."""
    rig = default_rig()
    return Rig(
        Camera(rig.camera.intrinsics.scaled(0.25)),
        Projector(rig.projector.intrinsics.scaled(0.25)),
        rig.proj2cam,
    )


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rig") / "quarter_rig.json"
    quarter_rig().save_json(path)
    return path


def _command(rig_file: Path, out: Path, *extra: str) -> list[str]:
    return [
        sys.executable, "-m", "virtus", "calibrate", "--rig", str(rig_file), "--board", "4x7",
        "--poses", f"random:{N_POSES}", "--spp", "1", "--seed", "5", "--out", str(out), *extra,
    ]  # fmt: skip


def _start(command: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=Path.cwd()
    )


#: ``python -c`` program: the CLI (arguments after the marker path) with the solve paused:
#: it touches the marker, then waits, so a test can kill the run during the solve without
#: racing its last steps (which take ~0.2 s and may be over before a busy machine polls).
_PAUSED_SOLVE = """
import pathlib, sys, time
import virtus.pipeline.calibrate as job
solve = job._solve
def paused(*args, **kwargs):
    pathlib.Path(sys.argv[1]).touch()
    time.sleep(120)
    return solve(*args, **kwargs)
job._solve = paused
from virtus.cli import main
main(sys.argv[2:])
"""


def _paused_before_solve(command: list[str], marker: Path) -> list[str]:
    """``command`` (a ``python -m virtus ...`` list) run with :data:`_PAUSED_SOLVE`."""
    assert command[1:3] == ["-m", "virtus"]
    return [command[0], "-c", _PAUSED_SOLVE, str(marker), *command[3:]]


def _run(command: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


def _contents(out: Path) -> dict[str, bytes]:
    files = sorted({p for pattern in COMPARED for p in out.glob(pattern) if p.is_file()})
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in files}


def _finished_poses(out: Path) -> dict[str, tuple[int, int, str]]:
    """Pose file -> (inode, mtime ns, SHA-256): a rewritten file changes at least one."""
    return {
        p.name: (p.stat().st_ino, p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
        for p in sorted((out / "poses").glob("*.npz"))
    }


def _rendered(log: list[str]) -> list[str]:
    return [line.split(" ", 1)[1] for line in log if line.startswith("rendered ")]


@pytest.fixture(scope="module")
def reference(rig_file, tmp_path_factory) -> Path:
    """An uninterrupted run, started together with a second run into the same directory:
    exactly one of them runs, the other is refused with one clear line."""
    out = tmp_path_factory.mktemp("reference")
    first, second = (_start(_command(rig_file, out)) for _ in range(2))
    results = [(p, p.wait(timeout=120), p.stderr.read()) for p in (first, second)]
    for process in (first, second):
        process.stderr.close()
    codes = sorted(code for _, code, _ in results)
    assert codes == [0, 2], results
    winner = next(p for p, code, _ in results if code == 0)
    refused = next(err for _, code, err in results if code == 2)
    assert refused.strip() == (
        f"virtus: error: {out} is in use by another virtus run (pid {winner.pid}); wait for "
        "it to finish or choose another output directory"
    )
    return out


def test_two_identical_runs_are_byte_identical(rig_file, reference, tmp_path):
    again = _run(_command(rig_file, tmp_path))
    assert again.returncode == 0, again.stderr
    expected = _contents(reference)
    assert len(expected) == 3 + 6 + N_POSES  # json, yaml, episode; 6 paper txt files; poses
    assert _contents(tmp_path) == expected
    # run.json too (no time stamps); timing.json is the one file allowed to differ.
    assert (tmp_path / "run.json").read_bytes() == (reference / "run.json").read_bytes()
    record = json.loads((reference / "run.json").read_text())
    assert record["status"] == "complete"
    assert sorted(_rendered(record["log"])) == [f"random_{i:03d}" for i in range(1, N_POSES + 1)]
    data = json.loads((reference / "calibration.json").read_text())
    assert "timing_s" not in data["settings"]
    assert abs(data["truth_error"]["camera"]["fx_rel_error"]) <= tol.CALIB_JOB_SMALL_FOCAL_REL
    assert set(json.loads((reference / "timing.json").read_text())["timing_s"]) == {
        "render_s",
        "observe_s",
        "calibrate_s",
    }


@pytest.mark.parametrize("finished", [1, 2, 3, 5, N_POSES], ids=lambda k: f"after_{k}_poses")
def test_killed_run_resumes_to_the_same_bytes_without_rendering_twice(
    rig_file, reference, tmp_path, finished
):
    """SIGKILL once ``finished`` pose files exist (all of them: during the solve, which
    the run pauses in until it is killed), then ``--resume``."""
    marker = tmp_path.parent / f"{tmp_path.name}.solving"
    command = _command(rig_file, tmp_path)
    if finished == N_POSES:
        command = _paused_before_solve(command, marker)
    process = _start(command)
    deadline = time.monotonic() + 120
    while len(list((tmp_path / "poses").glob("*.npz"))) < finished or (
        finished == N_POSES and not marker.exists()
    ):
        assert process.poll() is None, process.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(POLL_S)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    process.stderr.close()
    assert process.returncode == -signal.SIGKILL
    before = _finished_poses(tmp_path)
    assert len(before) >= finished
    killed = json.loads((tmp_path / "run.json").read_text())
    assert killed["status"] == "running"  # what a killed run leaves

    # Without --resume the directory is refused (it holds an unfinished run).
    refused = _run(_command(rig_file, tmp_path))
    assert refused.returncode == 2
    assert "pass --resume to continue it" in refused.stderr

    resumed = _run(_command(rig_file, tmp_path, "--resume"))
    assert resumed.returncode == 0, resumed.stderr
    assert _contents(tmp_path) == _contents(reference)
    # Finished poses were read back, not rendered again (same inode, time and bytes) ...
    after = _finished_poses(tmp_path)
    assert {name: after[name] for name in before} == before
    log = json.loads((tmp_path / "run.json").read_text())["log"]
    assert log.count("resume") == 1
    resume_at = log.index("resume")
    all_poses = {f"random_{i:03d}" for i in range(1, N_POSES + 1)}
    # ... every other pose was rendered exactly once after the resume, none twice overall.
    assert sorted(_rendered(log[resume_at:])) == sorted(all_poses - {n[:-4] for n in before})
    assert len(_rendered(log)) == len(set(_rendered(log)))
    assert not list(tmp_path.rglob(".virtus-tmp"))  # no temporary file left


def test_resume_with_other_settings_is_refused(rig_file, tmp_path):
    out = tmp_path / "run"
    process = _start(_command(rig_file, out))
    while not list((out / "poses").glob("*.npz")):
        assert process.poll() is None
        time.sleep(POLL_S)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    process.stderr.close()
    changed = _command(rig_file, out, "--resume")
    changed[changed.index("--seed") + 1] = "6"
    refused = _run(changed)
    assert refused.returncode == 2
    assert re.fullmatch(
        r"virtus: error: cannot resume in .*: it holds a `virtus calibrate` run \(running\) with "
        r"other settings \(config\.seed: 6 here, 5 in the existing run\); pass --overwrite to "
        r"start again\n",
        refused.stderr,
    ), refused.stderr


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--poses", "random:201", r"poses: expected 'paper' or 'random:N' with 3 <= N <= 200"),
        ("--poses", "random:99999999999", r"with 3 <= N <= 200, got 'random:99999999999'"),
        ("--seed", "-1", r"seed: expected an integer in 0\.\."),
    ],
)
def test_bad_options_are_refused_before_anything_is_done(tmp_path, option, value, message):
    from virtus.cli import main

    out = tmp_path / "out"
    command = ["calibrate", "--board", "4x7", "--out", str(out), option, value]
    result = subprocess.run(
        [sys.executable, "-m", "virtus", *command], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert re.search(message, result.stderr), result.stderr
    assert not out.exists()
    assert main is not None


def test_an_output_path_that_is_a_file_is_one_line_naming_it(tmp_path, capsys):
    from virtus.cli import main

    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(SystemExit) as info:
        main(["calibrate", "--poses", "random:3", "--out", str(blocker / "out")])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("virtus: error: ") and str(blocker) in err
    assert len(err.strip().splitlines()) == 1


def _poses() -> list[BoardPose]:
    """Three boards facing the camera squarely (at three distances and offsets), then two
    tilted by 20 deg about x and y."""
    fronto = [
        BoardPose(f"fronto_{k}", Pose(np.eye(3), t))
        for k, t in enumerate([(0.0, 0.0, 0.9), (0.02, 0.01, 1.0), (-0.02, 0.0, 1.1)])
    ]
    tilted = [
        BoardPose(f"tilted_{axis}", Pose.from_euler("xyz", angles, degrees=True, t=(0, 0, 1)))
        for axis, angles in (("x", (20, 0, 0)), ("y", (0, 20, 0)))
    ]
    return [*fronto, *tilted]


def test_fronto_parallel_poses_are_refused_not_solved(tmp_path):
    scanner = Scanner(rig=quarter_rig(), render=RenderSettings(spp=1))
    poses = _poses()
    with pytest.raises(VirtusError, match=r"3 usable board poses are nearly parallel"):
        calibrate_rig(scanner, board="4x7", poses=poses[:3], out_dir=tmp_path / "refused")
    assert not (tmp_path / "refused").exists()  # refused before anything is done
    calibrate_rig(scanner, board="4x7", poses=poses, out_dir=tmp_path)  # tilted: solvable
    # Without the tilted poses (as if their files were lost) the solve would return fx off
    # by ~80x; recalibrate refuses instead.
    for axis in "xy":
        (tmp_path / "poses" / f"tilted_{axis}.npz").unlink()
    written = (tmp_path / "calibration.json").read_bytes()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(VirtusError, match=r"normals 0\.00 deg < 5 deg\), so the focal"):
            recalibrate(tmp_path)
    assert [str(w.message).split(":")[1] for w in caught] == [
        " pose 'tilted_x' left out",
        " pose 'tilted_y' left out",
    ]
    assert (tmp_path / "calibration.json").read_bytes() == written  # nothing replaced


def test_observing_in_worker_processes_or_threads_gives_the_same_files(tmp_path, monkeypatch):
    scanner = Scanner(rig=quarter_rig(), render=RenderSettings(spp=1))
    options = {"board": "4x7", "poses": f"random:{N_POSES}", "rng": 5}
    here = calibrate_rig(scanner, out_dir=tmp_path / "here", processes=0, **options)
    workers = calibrate_rig(scanner, out_dir=tmp_path / "workers", processes=2, **options)
    threads = calibrate_rig(scanner, out_dir=tmp_path / "threads", **options)  # the default
    assert _contents(tmp_path / "workers") == _contents(tmp_path / "here")
    assert _contents(tmp_path / "threads") == _contents(tmp_path / "here")
    assert workers.rms_px == here.rms_px == threads.rms_px
    # As before the batched centroids (one window at a time): the same calibration.
    with monkeypatch.context() as patch:
        patch.setattr(detect, "_centroids", detect._centroids_per_circle)
        before = calibrate_rig(scanner, processes=0, **options)
    assert {k: round(v, 4) for k, v in before.rms_px.items()} == {
        k: round(v, 4) for k, v in threads.rms_px.items()
    }
    for name in ("camera", "projector"):
        was, now = (getattr(r.rig, name).intrinsics for r in (before, threads))
        np.testing.assert_allclose(now.K, was.K, rtol=1e-9)
        np.testing.assert_allclose(now.dist, was.dist, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(threads.rig.proj2cam.t, before.rig.proj2cam.t, rtol=1e-9)
    with pytest.raises(InputError, match="processes"):
        calibrate_rig(scanner, processes=99, **options)


def test_decoding_the_boards_window_gives_the_whole_frames_files(tmp_path, monkeypatch):
    # On the host only the board's window is decoded (pipeline.calibrate._rendered_view);
    # the whole frame's decode must give the same files, and so must a window too small
    # for the board (a valid pixel on its edge: the whole frame is decoded instead).
    from virtus.calib import scene
    from virtus.pipeline import calibrate

    scanner = Scanner(rig=quarter_rig(), render=RenderSettings(spp=1))
    options = {"board": "4x7", "poses": "random:4", "rng": 9, "processes": 0}
    window = calibrate_rig(scanner, out_dir=tmp_path / "window", **options)
    decoded: list[str] = []
    monkeypatch.setattr(scanner.sequence.__class__, "decode", _recording(decoded))
    monkeypatch.setattr(calibrate, "board_window", lambda *args: None)
    calibrate_rig(scanner, out_dir=tmp_path / "whole", **options)
    assert decoded == ["240x240"] * 4  # the whole frame, each pose
    decoded.clear()
    small = partial(scene.board_window, margin_px=-6)  # inside the board's outline
    monkeypatch.setattr(calibrate, "board_window", small)
    shrunk = calibrate_rig(scanner, out_dir=tmp_path / "shrunk", **options)
    assert len(decoded) == 8 and decoded[1::2] == ["240x240"] * 4  # window, then whole
    assert "240x240" not in decoded[::2]
    assert _contents(tmp_path / "whole") == _contents(tmp_path / "window")
    assert _contents(tmp_path / "shrunk") == _contents(tmp_path / "window")
    assert shrunk.rms_px == window.rms_px


def _recording(sizes: list[str]):
    """``PatternSequence.decode`` that appends each decoded frame size (``WxH``) to
    ``sizes``."""
    from virtus.patterns.sequence import PatternSequence

    decode = PatternSequence.decode

    def recorded(self, frames, **options):
        sizes.append(f"{frames.shape[2]}x{frames.shape[1]}")
        return decode(self, frames, **options)

    return recorded


def test_a_corrupt_pose_file_on_resume_is_one_line_naming_it(rig_file, reference, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(reference, out)
    pose = sorted((out / "poses").glob("*.npz"))[0]
    pose.write_bytes(b"PK\x03\x04 not a zip archive")
    result = _run(_command(rig_file, out, "--resume"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert str(pose) in lines[0] and "not a readable pose file" in lines[0]
