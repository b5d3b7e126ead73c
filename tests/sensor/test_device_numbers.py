"""Every numeric field of a sensor or projector file: its type, finiteness and range are
checked, and a bad one is an :class:`InputError` naming it -- never a ``TypeError`` or a
``ValueError`` from deep inside (:mod:`virtus.sensor.camera`, :mod:`virtus.sensor.projector`)."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.sensor.camera import Sensor, load_sensor
from virtus.sensor.projector import LEVELS, ProjectorModel, load_projector

NOT_NUMBERS = ["x", "5", True, [1], {"a": 1}, float("nan"), float("inf"), 10**400]
NOISY = {"system_gain_dn_per_e": 0.1}
RAMP = [i / LEVELS for i in range(LEVELS + 1)]


@pytest.mark.parametrize("value", NOT_NUMBERS, ids=repr)
@pytest.mark.parametrize(
    "name",
    ["exposure", "auto_percentile", "auto_target", "quantum_efficiency", "system_gain_dn_per_e",
     "saturation_capacity_e", "dark_noise_e", "dark_current_e_per_s", "exposure_time_s",
     "dsnu_e", "prnu", "black_level_dn", "bit_depth", "fixed_pattern_seed"],
)  # fmt: skip
def test_a_sensor_number_of_the_wrong_kind_names_its_field(name: str, value: object) -> None:
    with pytest.raises(InputError, match=rf"^{name}: expected") as error:
        Sensor(**{**NOISY, name: value})
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("name", "value"),
    [("auto_percentile", 0), ("auto_percentile", 100.5), ("auto_target", 0), ("auto_target", 2),
     ("quantum_efficiency", 0), ("system_gain_dn_per_e", -1), ("saturation_capacity_e", 0),
     ("exposure", -2), ("exposure", "manual"), ("fixed_pattern_seed", -1), ("bit_depth", 9.5),
     ("dsnu_e", -0.5)],
)  # fmt: skip
def test_a_sensor_number_out_of_range_names_its_field(name: str, value: object) -> None:
    with pytest.raises(InputError, match=rf"^{name}: expected"):
        Sensor(**{**NOISY, name: value})


def test_sensor_numbers_of_any_numeric_type_are_accepted(tmp_path) -> None:
    sensor = Sensor(
        bit_depth=np.int64(12), exposure=np.float32(3.0), auto_percentile=95,
        quantum_efficiency=np.float64(0.7), system_gain_dn_per_e=1, fixed_pattern_seed=np.uint8(4),
    )  # fmt: skip
    assert sensor.bit_depth == 12 and type(sensor.exposure) is float and sensor.full_scale == 4095
    assert Sensor(bit_depth=8.0).bit_depth == 8  # an integral float, as YAML may write it
    (tmp_path / "cam.yaml").write_text("auto_percentile: x\n")
    with pytest.raises(InputError, match=r"^auto_percentile: expected a percentile in \(0, 100\]"):
        load_sensor(tmp_path / "cam.yaml")
    (tmp_path / "cam.yaml").write_text("auto_percentile: 97.5\nexposure: 20\n")
    assert load_sensor(tmp_path / "cam.yaml").auto_percentile == 97.5


@pytest.mark.parametrize(
    ("lut", "got"),
    [
        (5, "5"), ("ramp", "'ramp'"), ({"a": 1}, "{'a': 1}"), (["a", "b"], "'2 values'"),
        (["a"] * 256, "'index 0: a'"), ([[0, 1]] * 256, "'index 0: [0, 1]'"),
        ([*RAMP[:3], True, *RAMP[4:]], "'index 3: True'"),
        ([*RAMP[:3], float("nan"), *RAMP[4:]], "'index 3: nan'"),
        ([*RAMP[:3], -0.1, *RAMP[4:]], "'index 3: -0.1'"),
        ([*RAMP[:3], 0.0, *RAMP[4:]], "'index 3: 0.0 after"), ([*RAMP[:-1], 0.9999], "index 255"),
        ([*RAMP[:3], 10**400, *RAMP[4:]], "'index 3: 1000"),
    ],
    ids=["number", "string", "mapping", "short", "strings", "nested", "bool", "nan", "negative",
         "decreasing", "end", "huge-int"],
)  # fmt: skip
def test_a_bad_response_lut_is_named_with_the_entry_at_fault(lut: object, got: str) -> None:
    with pytest.raises(InputError, match=r"^response_lut: expected") as error:
        ProjectorModel.from_dict({"response_lut": lut})
    assert got in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("name", "value"),
    [("gamma", "2.2"), ("gamma", True), ("gamma", [2.2]), ("contrast_ratio", "high"),
     ("contrast_ratio", 10**400), ("fill_factor", np.nan), ("psf_sigma_px", "wide"),
     ("name", ""), ("name", 3), ("precompensate", 1)],
)  # fmt: skip
def test_a_projector_field_of_the_wrong_kind_names_itself(name: str, value: object) -> None:
    with pytest.raises(InputError, match=rf"^{name}: expected"):
        ProjectorModel(**{"pixel": "psf", name: value})


def test_a_measured_response_is_still_read(tmp_path) -> None:
    (tmp_path / "dlp.yaml").write_text(f"response_lut: {[x**2.2 for x in RAMP]}\n")
    model = load_projector(tmp_path / "dlp.yaml")
    assert len(model.response_lut) == 256 and model.response_lut[-1] == 1.0
    assert ProjectorModel(response_lut=np.array(RAMP)).response_lut == tuple(RAMP)
    assert ProjectorModel.from_dict(model.to_dict()) == model
