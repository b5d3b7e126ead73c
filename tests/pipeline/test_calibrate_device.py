"""``calibrate_rig`` on the device path (taken on a GPU; forced here on ``llvm_ad_rgb``, the
CPU twin of ``cuda_ad_rgb``): the poses are decoded on the device and only the maps the
calibration observes are copied (``Scanner.decoded_maps``); the files are byte for byte
those of observing the whole decode's maps.
"""

from __future__ import annotations

import pytest

from tests.pipeline.test_calibrate_resume import _contents, quarter_rig
from virtus.pipeline.calibrate import calibrate_rig
from virtus.render import RenderSettings
from virtus.render.jit.decode import DeviceDecode
from virtus.scanner import DecodedMaps, Scanner

pytestmark = pytest.mark.slow


def test_observing_the_copied_maps_gives_the_whole_decodes_files(tmp_path, monkeypatch):
    scanner = Scanner(rig=quarter_rig(), render=RenderSettings(spp=1, variant="llvm_ad_rgb"))
    monkeypatch.setattr(Scanner, "renders_on_gpu", property(lambda self: True))
    options = {"board": "4x7", "poses": "random:4", "rng": 9, "processes": 0}
    copied: list[tuple[str, ...]] = []
    host_fields = DeviceDecode._host_fields

    def recording(self, sequence, names):
        copied.append(tuple(names))
        return host_fields(self, sequence, names)

    monkeypatch.setattr(DeviceDecode, "_host_fields", recording)
    maps = calibrate_rig(scanner, out_dir=tmp_path / "maps", **options)
    assert copied == [("proj_uv", "background")] * 4  # each pose, on the device path

    def whole(self, scene, fields, **kwargs):  # the whole decode, its maps picked here
        view = self.decoded_view(scene, **kwargs)
        return DecodedMaps({name: getattr(view.decoded, name) for name in fields}, view.white)

    monkeypatch.setattr(Scanner, "decoded_maps", whole)
    reference = calibrate_rig(scanner, out_dir=tmp_path / "whole", **options)
    assert len(copied) == 4
    assert _contents(tmp_path / "maps") == _contents(tmp_path / "whole")
    assert maps.rms_px == reference.rms_px
