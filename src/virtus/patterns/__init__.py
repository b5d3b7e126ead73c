"""Fringe patterns as data, numpy only: coding and decoding of the pattern sets labs use.

* :mod:`~virtus.patterns.sequence` -- ``PatternSequence``: frames, codings, decode plans, files.
* :mod:`~virtus.patterns.phase` -- decoding math: wrapped phase, masks, unwrapping.
"""

from virtus.patterns import phase
from virtus.patterns.sequence import (
    CODE_FLAG_RAD,
    DEFAULT_HETERODYNE_PERIODS,
    DIRECTIONS,
    FLAG_WARN_FRACTION,
    KINDS,
    MAX_BITS,
    MAX_FRAMES,
    RESIDUAL_FLAG_RAD,
    BitCode,
    CodePlan,
    DecodePlan,
    DecodeResult,
    DecodeWarning,
    Frame,
    PatternSequence,
    PhaseCoding,
    PhaseSet,
    build_sequence,
    default_sequence,
    gray_bits_needed,
    heterodyne_sequence,
    load_sequence_file,
)

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
    "phase",
]
