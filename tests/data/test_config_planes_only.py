"""objects.count may be 0 in training mode: samples of background planes only (the
flat-plane out-of-distribution test set of virtus.learn); other modes and empty scenes are
refused."""

from __future__ import annotations

import numpy as np
import pytest

from tests.data.test_dataset import tiny_config
from virtus.data import DatasetStore, generate, load_config
from virtus.errors import InputError


def test_planes_only_samples_have_no_object(tmp_path) -> None:
    config = tiny_config(tmp_path, num_samples=2, objects={"count": [0, 0]})
    generate(load_config(config), tmp_path / "store")
    store = DatasetStore.open(tmp_path / "store")
    for index, meta in store.samples().items():
        assert [o["type"] for o in meta["objects"]] == ["plane"]
        depth = store.read_sample(index, ("depth",))["depth"]
        assert np.isfinite(depth).mean() > 0.9  # the plane fills the view


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"objects": {"count": [0, 0]}, "planes": {"count": [0, 1]}}, "objects.count"),
        ({"mode": "scan", "objects": {"count": [0, 1]}}, "objects.count"),
    ],
)
def test_empty_scenes_are_refused(tmp_path, changes, message) -> None:
    with pytest.raises(InputError, match=message):
        load_config(tiny_config(tmp_path, **changes))
