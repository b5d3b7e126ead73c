"""Fringe patterns as data, numpy only: coding and decoding of the pattern sets labs use.

* :mod:`~virtus.patterns.codings` -- phase shifting and Gray/binary codes, and the conventions.
* :mod:`~virtus.patterns.frames` -- frame kinds, directions and the ``Frame`` record.
* :mod:`~virtus.patterns.sequence` -- ``PatternSequence``: frames that encode and plan their decode.
* :mod:`~virtus.patterns.decode` -- decode plans, the decode driver and ``DecodeResult``.
* :mod:`~virtus.patterns.files` -- the sequence description file (YAML/JSON), read and written.
* :mod:`~virtus.patterns.catalog` -- built-in sequences: the paper's default, heterodyne,
  OpenCV's Gray code alone.
* :mod:`~virtus.patterns.phase` -- decoding math: wrapped phase, masks, unwrapping.
"""

from virtus.patterns import phase
from virtus.patterns.catalog import (
    DEFAULT_HETERODYNE_PERIODS,
    build_sequence,
    default_sequence,
    heterodyne_sequence,
    opencv_graycode_sequence,
)
from virtus.patterns.codings import MAX_BITS, BitCode, PhaseCoding, gray_bits_needed
from virtus.patterns.decode import (
    CODE_FLAG_RAD,
    FLAG_WARN_FRACTION,
    RESIDUAL_FLAG_RAD,
    CodePlan,
    DecodePlan,
    DecodeResult,
    DecodeWarning,
    PhaseSet,
)
from virtus.patterns.files import load_sequence_file
from virtus.patterns.frames import DIRECTIONS, KINDS, MAX_FRAMES, Frame
from virtus.patterns.sequence import PatternSequence

__all__ = [
    "BitCode",
    "CODE_FLAG_RAD",
    "CodePlan",
    "DEFAULT_HETERODYNE_PERIODS",
    "DIRECTIONS",
    "DecodePlan",
    "DecodeResult",
    "DecodeWarning",
    "FLAG_WARN_FRACTION",
    "Frame",
    "KINDS",
    "MAX_BITS",
    "MAX_FRAMES",
    "PatternSequence",
    "PhaseCoding",
    "PhaseSet",
    "RESIDUAL_FLAG_RAD",
    "build_sequence",
    "default_sequence",
    "gray_bits_needed",
    "heterodyne_sequence",
    "load_sequence_file",
    "opencv_graycode_sequence",
    "phase",
]
