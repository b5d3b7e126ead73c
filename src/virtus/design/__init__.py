"""Design a scanner before building it: predictions and sweeps over the rig, the fringes
and the sensor, and the virtual acceptance test.

* :mod:`~virtus.design.modulation` -- the noise-free ground-truth signal pass of a pose.
* :mod:`~virtus.design.montecarlo` -- the uncertainty model against noisy re-renders.
* :mod:`~virtus.design.predict` -- ``virtus predict``: per-pixel sigma maps of a scene.
* :mod:`~virtus.design.variants` -- the keys a design sweep varies and the scanner each
  variant builds.
* :mod:`~virtus.design.sweep` -- ``virtus design``: predicted noise over the variants.
* :mod:`~virtus.design.volume` -- the measuring volume of a rig (or a given box).
* :mod:`~virtus.design.artefacts` -- VDI/VDE 2634-2 artefacts, their sizes and positions.
* :mod:`~virtus.design.figures` -- P_F, P_S, SD, F from point maps, and their predictions.
* :mod:`~virtus.design.acceptance` -- ``virtus acceptance``: the virtual acceptance test.

Units: SI inside; summaries in projector px (``*_px``) and micrometres (``*_um``).
"""

from virtus.design.acceptance import AcceptanceResult, acceptance_test, parse_limits
from virtus.design.artefacts import ArtefactPosition, Artefacts, artefact_layout
from virtus.design.modulation import SignalPass, predict_pass, signal_pass
from virtus.design.montecarlo import MonteCarlo, monte_carlo
from virtus.design.predict import predict_scene
from virtus.design.sweep import FIGURES, TARGETS, design_target, predict_variant, run_design
from virtus.design.variants import KEYS, Variant, overlap_fraction, parse_vary, variants
from virtus.design.volume import (
    MeasuringVolume,
    check_volume,
    volume_from_rig,
    volume_from_text,
)

__all__ = [
    # -- predictions and sweeps (virtus predict, virtus design) --
    "FIGURES",
    "KEYS",
    "MonteCarlo",
    "SignalPass",
    "TARGETS",
    "Variant",
    "design_target",
    "monte_carlo",
    "overlap_fraction",
    "parse_vary",
    "predict_pass",
    "predict_scene",
    "predict_variant",
    "run_design",
    "signal_pass",
    "variants",
    # -- acceptance test (virtus acceptance) --
    "AcceptanceResult",
    "ArtefactPosition",
    "Artefacts",
    "MeasuringVolume",
    "acceptance_test",
    "artefact_layout",
    "check_volume",
    "parse_limits",
    "volume_from_rig",
    "volume_from_text",
]
