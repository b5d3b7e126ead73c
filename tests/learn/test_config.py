"""The training configuration (virtus.learn.config): defaults are FPP-ML-Bench's, bad keys
and values are named."""

from __future__ import annotations

import pytest
import yaml

from virtus.errors import InputError
from virtus.learn.config import TrainConfig, load_train_config


def test_defaults_and_round_trip(tmp_path) -> None:
    config = TrainConfig()
    assert (config.lr, config.weight_decay, config.alpha) == (1e-4, 1e-5, 0.7)
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump({"model": "phase", "input_frame": 2}))
    loaded = load_train_config(path)
    assert loaded.model == "phase" and loaded.input_frame == 2
    assert TrainConfig.from_dict(loaded.to_dict()) == loaded


@pytest.mark.parametrize(
    ("data", "name"),
    [
        ({"model": "resnet"}, "model"),
        ({"lr": 0}, "lr"),
        ({"batch_size": True}, "batch_size"),
        ({"input_frame": -1}, "input_frame"),
        ({"amp": "yes"}, "amp"),
        ({"direction": "x"}, "direction"),
        ({"epoch": 3}, "epoch"),
    ],
)
def test_bad_values_are_named(data, name) -> None:
    with pytest.raises(InputError, match=name):
        TrainConfig.from_dict(data)
