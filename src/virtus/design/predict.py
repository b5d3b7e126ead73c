"""``virtus predict``: per-pixel predicted noise of a scanner looking at a scene.

One noise-free ground-truth pass of the scene (:func:`virtus.design.modulation.signal_pass`),
then the uncertainty model (:func:`virtus.uncertainty.predict_uncertainty`): no noisy frame
is rendered.

Output directory (owned through :func:`virtus.io.runs.claim_run`, command ``predict``)::

    OUT/run.json, OUT/.virtus.lock   the run record and lock
    OUT/sigma_u_p.npy                (H, W) float64 projector px: sigma of the decoded u_p
    OUT/sigma_v_p.npy                (H, W) float64 projector px: of v_p (NaN if not coded)
    OUT/sigma_depth.npy              (H, W) float64 metres: of the camera-frame depth z
    OUT/sigma_range.npy              (H, W) float64 metres: along the camera ray
    OUT/sigma_point.npy              (H, W) float64 metres: sqrt(trace of the covariance)
    OUT/mask.npy                     (H, W) bool: pixels with a prediction
    OUT/summary.json                 median and 95th percentile of each map (px, um), the
                                     exposure, the scanner and the scene it describes
    OUT/scene_assets/*               a built-in scene's assets

NaN marks pixels without a prediction (no surface, shadowed, outside the projector,
saturated, not triangulated).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.design.modulation import predict_pass, signal_pass
from virtus.errors import InputError
from virtus.io.runs import claim_run
from virtus.pipeline.inputs import resolve_scene
from virtus.reconstruct import as_use
from virtus.scanner import Scanner
from virtus.scene.builtin import BUILTIN_SCENES
from virtus.uncertainty import Prediction

__all__ = ["COMMAND", "SUMMARY_JSON", "predict_scene"]

#: The job's name in ``run.json``.
COMMAND = "predict"
SUMMARY_JSON = "summary.json"
MASK_NPY = "mask.npy"
LAYOUT = (*(f"{n}.npy" for n in Prediction.MAP_NAMES), MASK_NPY, SUMMARY_JSON, "scene_assets/*")


def predict_scene(
    out_dir: str | Path,
    scene: str | Path,
    scanner: Scanner | None = None,
    *,
    use: str = "uv",
    overwrite: bool = False,
) -> dict[str, Any]:
    """Predict the per-pixel noise of ``scanner`` on ``scene`` and write the maps.

    Parameters
    ----------
    out_dir : directory owned by the run (layout in the module docstring).
    scene : a built-in scene name (:data:`virtus.scene.builtin.BUILTIN_SCENES`) or a scene
        file (YAML or USD).
    scanner : the scanner (default: the paper's system).
    use : which decoded coordinates triangulate (``uv``, ``u`` or ``v``).
    overwrite : remove an earlier run's files first.

    Returns
    -------
    The summary written to ``summary.json``.
    """
    scanner = scanner or Scanner()
    use = as_use(use).value
    text = str(scene)
    if text not in BUILTIN_SCENES and not Path(text).is_file():
        raise InputError(
            "--scene", f"an existing scene file or one of {', '.join(BUILTIN_SCENES)}", text
        )
    scanner.check()
    for direction in {"uv": ("v", "h"), "u": ("v",), "v": ("h",)}[use]:
        plan = scanner.sequence.plan(direction)
        if plan is None or not plan.sets:
            raise InputError(
                "--use", f"coordinates the sequence codes with phase frames (direction "
                f"{direction!r} has none)", use,
            )  # fmt: skip
    config = {"scanner": scanner.to_dict(), "scene": text, "use": use}
    inputs = {} if text in BUILTIN_SCENES else {"scene": text}
    with claim_run(
        out_dir, COMMAND, config, inputs=inputs, layout=LAYOUT, overwrite=overwrite
    ) as run:
        resolved = resolve_scene(text, run.file("scene_assets"))
        assets = sorted(run.file("scene_assets").glob("*")) if text in BUILTIN_SCENES else []
        run.own(*(f"scene_assets/{p.name}" for p in assets))
        passed = signal_pass(scanner, resolved)
        prediction = predict_pass(passed, use=use)
        for name, values in prediction.maps().items():
            run.write(f"{name}.npy", lambda tmp, v=values: np.save(tmp, v))
        run.write(MASK_NPY, lambda tmp: np.save(tmp, prediction.mask))
        summary = {
            "units": {"*_px": "projector px", "*_um": "micrometres", "maps": "metres, npy"},
            **prediction.summary(),
            "lit_pixels": int(passed.gt.mask.sum()),
            "exposure_dn_per_radiance": passed.exposure,
            "sensor": scanner.sensor.name,
            "scene": text,
            "use": use,
        }  # fmt: skip
        run.write_json(SUMMARY_JSON, summary, allow_nan=False)
        return summary
