"""The sensor models of a scan; pure numpy, shared by the host and device renderers.

* :mod:`~virtus.sensor.camera` -- the EMVA 1288 camera (``Sensor``) and its presets.
* :mod:`~virtus.sensor.projector` -- projector response, pixel shape, lens blur
  (``ProjectorModel``).
* :mod:`~virtus.sensor.noise` -- counter-based random streams keyed by (seed, frame, pixel).
"""

from virtus.sensor.camera import SENSOR_PRESETS, Sensor, load_sensor
from virtus.sensor.noise import MAX_SEED, NOISE_STREAM, as_seed, pcg4d, standard_normal, stream_key
from virtus.sensor.projector import (
    Lookup,
    ProjectorModel,
    as_lookup,
    load_projector,
)

__all__ = [
    "MAX_SEED",
    "NOISE_STREAM",
    "SENSOR_PRESETS",
    "Lookup",
    "ProjectorModel",
    "Sensor",
    "as_lookup",
    "as_seed",
    "load_projector",
    "load_sensor",
    "pcg4d",
    "standard_normal",
    "stream_key",
]
