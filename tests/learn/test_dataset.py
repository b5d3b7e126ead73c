"""The training dataset over a store (virtus.learn.dataset): inputs scaled to [0, 1], metric
depth, objects without the background plane, phase labels, the sample's own layer."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from virtus.data import FringeDataset  # noqa: E402
from virtus.learn.dataset import LearnDataset  # noqa: E402


def test_items_follow_the_store(learn_store) -> None:
    data = LearnDataset(learn_store, "train", "phase")
    raw = FringeDataset(learn_store, "train", tensors=False)
    assert len(data) == len(raw) > 0
    item, ref = data[0], raw[0]
    frame = data.frames[0]
    assert raw.meta(0)["sequence"]["frames"][frame]["kind"] == "phase"
    np.testing.assert_allclose(item["image"][0].numpy(), ref["frames"][frame] / 255.0, atol=1e-7)
    surface = np.isfinite(ref["depth"])
    np.testing.assert_array_equal(item["surface"].numpy(), surface)
    np.testing.assert_array_equal(item["depth"].numpy()[surface], ref["depth"][surface])
    plane = [o["id"] for o in raw.meta(0)["objects"] if o["type"] == "plane"]
    assert plane and not item["object"].numpy()[np.isin(ref["object_id"], plane)].any()
    assert item["object"].any()
    valid = item["valid"].numpy()
    np.testing.assert_array_equal(item["wrapped"].numpy()[valid], ref["wrapped"][0][valid])
    assert (item["order"].numpy()[~valid] == -1).all()
    # the layer of the sample turns its exact phase into its depth
    layer, period = data.layer(0)
    phase = torch.from_numpy(np.where(valid, ref["phase"][0], np.nan).astype(np.float64))
    depth = layer.depth(phase * period / (2 * np.pi)).numpy()
    assert np.nanmax(np.abs(depth[valid] - ref["depth"][valid])) < 1e-5  # float32 labels


def test_decoded_phase_matches_the_labels(learn_store) -> None:
    data = LearnDataset(learn_store, "test", "phase")
    raw = FringeDataset(learn_store, "test", ("phase",), tensors=False)
    for item in range(len(data)):
        label = raw[item]["phase"][0]
        decoded = data.decoded_phase(item)
        both = np.isfinite(label) & np.isfinite(decoded)
        assert both.sum() > 0.5 * np.isfinite(label).sum()  # the decode covers the lit pixels
        # sharp DMD pixels: a staircase up to half a projector px (0.2 rad at T = 16); a
        # wrong order is off by 2 pi
        error = np.abs(decoded[both] - label[both])
        assert np.mean(error < 0.3) > 0.99 and np.median(error) < 0.15


def test_horizontal_fringes_give_the_h_labels_and_layer(horizontal_store) -> None:
    """``direction="h"``: the input frame, the labels and the depth layer are those of the
    horizontal fringes (a rig whose baseline is vertical measures depth with them)."""
    data = LearnDataset(horizontal_store, None, "phase", direction="h")
    raw = FringeDataset(horizontal_store, None, tensors=False)
    frames = raw.meta(0)["sequence"]["frames"]
    first = frames[data.frames[0]]
    assert first["kind"] == "phase" and first["direction"] == "h" and first["step"] == 1
    item, ref = data[0], raw[0]
    valid = item["valid"].numpy()
    assert valid.mean() > 0.5
    np.testing.assert_array_equal(item["wrapped"].numpy()[valid], ref["wrapped"][1][valid])
    layer, period = data.layer(0)
    assert layer.axis == 1
    phase = torch.from_numpy(np.where(valid, ref["phase"][1], np.nan).astype(np.float64))
    depth = layer.depth(phase * period / (2 * np.pi)).numpy()
    assert np.nanmax(np.abs(depth[valid] - ref["depth"][valid])) < 1e-5  # float32 labels
    decoded = data.decoded_phase(0)
    both = np.isfinite(decoded) & valid
    assert np.median(np.abs(decoded[both] - ref["phase"][1][both])) < 0.15
