"""``virtus predict`` (virtus.design.predict): sigma maps and their summary of a scene."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support import small_rig
from virtus.cli import main
from virtus.design.predict import predict_scene
from virtus.errors import InputError
from virtus.patterns import build_sequence
from virtus.render.settings import RenderSettings
from virtus.scanner import Scanner
from virtus.sensor import SENSOR_PRESETS
from virtus.uncertainty import Prediction


def _scanner(**changes):
    rig = small_rig(1 / 10)  # 96 x 96 px
    return Scanner(rig=rig, sensor=SENSOR_PRESETS["webcam"], render=RenderSettings(spp=1)).with_(
        **changes
    )


def test_predict_writes_the_maps_and_a_summary_that_describes_them(tmp_path):
    summary = predict_scene(tmp_path / "out", "sphere", _scanner())
    out = tmp_path / "out"
    maps = {name: np.load(out / f"{name}.npy") for name in Prediction.MAP_NAMES}
    mask = np.load(out / "mask.npy")
    assert all(m.shape == (96, 96) for m in maps.values()) and mask.dtype == bool
    assert np.all(np.isfinite(maps["sigma_depth"][mask]))
    assert np.all(np.isnan(maps["sigma_depth"][~mask]))
    assert summary == json.loads((out / "summary.json").read_text())
    assert summary["pixels"] == mask.sum() > 0.5 * mask.size
    depth_um = maps["sigma_depth"][mask] * 1e6
    assert summary["sigma_depth_um_median"] == pytest.approx(np.median(depth_um))
    assert summary["sigma_depth_um_p95"] == pytest.approx(np.percentile(depth_um, 95))
    # the point's sigma bounds its components; the ray's is close to depth's (ray ~ z axis)
    assert np.all(maps["sigma_point"][mask] >= maps["sigma_depth"][mask])
    assert 0.9 < np.median(maps["sigma_range"][mask] / maps["sigma_depth"][mask]) < 1.1


def test_predict_refuses_bad_input_before_writing(tmp_path):
    with pytest.raises(InputError, match="--scene"):
        predict_scene(tmp_path / "out", "no-such-scene.yaml", _scanner())
    vertical = build_sequence(912, 1140, periods=18.0, steps=4, gray_bits=7, directions=("v",))
    with pytest.raises(InputError, match="direction 'h' has none"):
        predict_scene(tmp_path / "out", "sphere", _scanner(sequence=vertical), use="uv")
    assert not (tmp_path / "out").exists()


def test_cli_predict_prints_the_summary(tmp_path, capsys):
    rig = tmp_path / "rig.json"
    small_rig(1 / 12).save_json(rig)
    with pytest.raises(SystemExit) as exit_info:
        main(["predict", "--scene", "sphere", "--rig", str(rig), "--spp", "1", "--sensor",
              "imx174", "--out", str(tmp_path / "out"), "--json"])  # fmt: skip
    assert exit_info.value.code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["sensor"] == "imx174" and data["sigma_u_p_px_median"] > 0
    with pytest.raises(SystemExit) as exit_info:
        main(["predict", "--scene", "missing.yaml", "--out", str(tmp_path / "bad")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--scene: expected an existing scene file" in err
    assert not (tmp_path / "bad").exists()
