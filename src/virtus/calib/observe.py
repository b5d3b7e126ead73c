"""Pose observation: from one board pose's capture to what the solver needs -- the board
points in the camera image and the local camera->projector homographies around them.

:func:`observe_pose` reads a capture (rendered or real) and decodes it;
:func:`observe_arrays` works on what it reads (decoded projector coordinates, the phase
background, the white frame), so the calibration job can observe rendered poses in worker
threads or processes (:mod:`virtus.calib.observers`). Both give a
:class:`~virtus.calib.solve.PoseObservation` for
:func:`virtus.calib.solve.calibrate_observations`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.calib.arrayspace import start_linear_algebra
from virtus.calib.board import Board
from virtus.calib.detect import find_grid, refine_points
from virtus.calib.projector import local_homographies
from virtus.calib.solve import PoseObservation
from virtus.capture.capture import Capture
from virtus.errors import InputError

__all__ = [
    "check_sequence",
    "observation_device",
    "observe_arrays",
    "observe_pose",
    "uniform_image",
]


def check_sequence(sequence: Any) -> None:
    """Refuse a sequence that cannot calibrate a projector: it needs both directions
    (``u_p`` and ``v_p`` at every board point), each decoded from phase frames or from a
    Gray or binary code alone (OpenCV's ``GrayCodePattern``: integer stripe centres, which
    the local homographies turn into sub-pixel projector points)."""
    if tuple(sequence.directions) != ("v", "h"):
        raise InputError(
            "sequence",
            "phase frames in both directions (v and h), or a Gray or binary code alone in "
            "both, to calibrate the projector",
            f"directions {list(sequence.directions)}",
        )


def uniform_image(frames: np.ndarray, sequence: Any, background: np.ndarray) -> np.ndarray:
    """The board under uniform light, where :func:`observe_arrays` refines its points.

    With phase frames this is the decoded ``background`` (the mean of every phase frame).
    A sequence of codes alone has no phase frames: its decoded background is
    ``(white + black) / 2``, two frames' noise, so the board is refined on the mean of
    every complete pattern/inverse pair and of white and black instead (each pair adds up
    to white plus black for a linear camera: measured with the ``imx174`` sensor at
    480 x 480 px and OpenCV's Gray code, the error of 6x9 checkerboard corners falls from
    0.012 to 0.0085 px RMS, of 7x13 circle centroids from 0.0040 to 0.0027 px).

    Parameters
    ----------
    frames : (F, H, W) the capture's frames, in sequence order.
    sequence : its :class:`~virtus.patterns.PatternSequence`.
    background : (H, W) the decoded background, returned as it is for other sequences.
    """
    plans = sequence.plans()
    if not plans or any(plan.method != "code_only" for plan in plans.values()):
        return background
    kinds = [frame.kind for frame in sequence.frames]
    pairs = [
        (normal, inverse)
        for plan in plans.values()
        for normal, inverse in zip(plan.code.normal, plan.code.inverse, strict=True)
        if normal is not None and inverse is not None
    ]
    uniform = [[i for i, kind in enumerate(kinds) if kind == name] for name in ("white", "black")]
    total = np.zeros(np.shape(background), dtype=np.float64)
    for normal, inverse in pairs:
        total += frames[normal].astype(np.float64) + frames[inverse]
    count = len(pairs)
    if all(uniform):
        total += frames[uniform[0]].mean(axis=0, dtype=np.float64)
        total += frames[uniform[1]].mean(axis=0, dtype=np.float64)
        count += 1
    return background if count == 0 else total / (2 * count)


def observe_pose(capture: Capture, board: Board, name: str) -> PoseObservation:
    """Detect the board and fit the projector homographies from one pose's capture.

    Parameters
    ----------
    capture : the pose's capture; its sequence must have phase frames in both directions
        (any coding: Gray, heterodyne, ...; white and black frames optional) or a Gray or
        binary code alone in both (:func:`check_sequence`).
    board : the board.
    name : the pose's name.

    Notes
    -----
    The circles are found in the white frame if the sequence has one, else in the phase
    background ``A`` (the board under uniform light: the fringes average out), and their
    centroids are refined on ``A``, where each frame's rounding is averaged out (on the
    paper's sequence this cuts the centroid error from 0.0033 to 0.0014 px against the
    white frame); a sequence of codes alone refines them on its pairs' mean
    (:func:`uniform_image`). Projector coordinates come from :meth:`Capture.decode`: for a
    code alone, the centre of each pixel's stripe (an integer projector column and row for
    a code per projector pixel), valid where every bit's contrast passes the decode's
    ``min_contrast``; the local homographies fitted over hundreds of such pixels give
    sub-pixel projector points, as Moreno & Taubin (2012) do with Gray codes.
    """
    check_sequence(capture.sequence)
    kinds = [frame.kind for frame in capture.sequence.frames]
    white = capture.frames[kinds.index("white")] if "white" in kinds else None
    decoded = capture.decode()
    image = uniform_image(capture.frames, capture.sequence, decoded.background)
    stripes = [s for s in (decoded.stripe_v, decoded.stripe_h) if s is not None]
    stripe = max(stripes) if stripes else None
    return observe_arrays(decoded.proj_uv, image, white, board, name, stripe=stripe)


def observe_arrays(
    proj_uv: np.ndarray,
    background: np.ndarray,
    white: np.ndarray | None,
    board: Board,
    name: str,
    *,
    stripe: float | None = None,
    device: str | None = None,
) -> PoseObservation:
    """:func:`observe_pose` from what it reads of a pose: the decoded projector coordinates
    (H, W, 2) px, the phase background (H, W) (:func:`uniform_image`) and the white frame
    (H, W), or None to detect on the background; ``stripe``: the widest stripe (projector
    px) of a direction decoded from a code alone, None without one
    (:func:`~virtus.calib.projector.local_homographies`); ``device``: where the circles'
    centroids and the local homographies are computed (:func:`observation_device`; None: numpy
    here). Detection (OpenCV) is on the host."""
    centres = find_grid(background if white is None else white, board)
    if centres is None:
        return PoseObservation(name, None, None)
    centroids = refine_points(background, board, centres, device=device)
    homographies = local_homographies(proj_uv, board, centres, stripe=stripe, device=device)
    return PoseObservation(name, centroids, homographies)


def observation_device(on_gpu: bool) -> str | None:
    """Where a calibration whose poses are rendered on a GPU (``on_gpu``) computes their
    circles' centroids and local homographies: ``"cuda"`` when torch is installed and sees
    a CUDA device, else None (numpy on the host, as always without a GPU).

    Both are elementwise work over every padded window pixel (~5e5 a pose at the paper's
    960 px), about two thirds of a pose's observation on a CPU core; on the device they
    leave the host's cores to detection (``benchmarks/bench_calibrate.py``). The results
    differ from the host's by rounding (centroids and projector points ~1e-12 px).
    """
    if not on_gpu:
        return None
    try:
        import torch
    except ImportError:
        return None
    if not torch.cuda.is_available():
        return None
    start_linear_algebra("cuda")  # here, before the observer threads
    return "cuda"
