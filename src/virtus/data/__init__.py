"""Synthetic FPP datasets at scale: configuration, randomisation, Zarr store, loaders.

One concept per module:

* :mod:`virtus.data.config` -- the validated configuration (:class:`DatasetConfig`,
  :func:`load_config`; YAML schema in its docstring).
* :mod:`virtus.data.sampling` -- domain randomisation: sample ``i`` from
  ``(seed, i, config)`` only; splits by object (:class:`Randomiser`).
* :mod:`virtus.data.labels` -- the arrays of a sample, labels exact from the ground truth.
* :mod:`virtus.data.store` -- the sharded Zarr v3 (or PNG) store and its manifest
  (:class:`DatasetStore`; layout in its docstring).
* :mod:`virtus.data.chunkcodecs` -- how chunks are compressed and who encodes them
  (numcodecs on the CPU, nvCOMP on a GPU; the stored format is plain Zarr either way).
* :mod:`virtus.data.integrity` -- what a store's description, records and samples must be
  to be read (:class:`DamagedSample`: every read is checked against its checksum).
* :mod:`virtus.data.generate` -- rendering missing shards here, in processes or on Ray
  (:func:`generate`), resumable after any interruption.
* :mod:`virtus.data.shardtask` -- one shard task: render, label and write a shard's
  samples, wherever it runs; :mod:`virtus.data.devicebuffers` -- the device and
  page-locked buffers of samples made and compressed on a GPU;
  :mod:`virtus.data.workerimports` -- what a worker needs, imported once by the server
  that forks the workers.
* :mod:`virtus.data.loaders` -- :class:`FringeDataset` (PyTorch map-style; torch optional).
* :mod:`virtus.data.export` -- WebDataset tar shards (:func:`export_webdataset`).
* :mod:`virtus.data.mlbench` -- FPP-ML-Bench's layout (:func:`export_fpp_ml_bench`) and the
  single-shot input frame of a sample (:func:`input_frame_index`).

Example::

    from virtus.data import FringeDataset, generate, load_config

    generate(load_config("examples/datasets/training.yaml"), "out/train.zarr", num=100)
    dataset = FringeDataset("out/train.zarr", split="train")
    item = dataset[0]               # dict of tensors: frames, depth (m), phase (2, H, W) rad, ...
"""

from virtus.data.config import DatasetConfig, load_config
from virtus.data.export import export_webdataset
from virtus.data.generate import GenerateReport, generate
from virtus.data.integrity import DamagedSample
from virtus.data.loaders import FringeDataset
from virtus.data.mlbench import export_fpp_ml_bench, input_frame_index
from virtus.data.store import DatasetStore, VerifyReport

__all__ = [
    "DamagedSample",
    "DatasetConfig",
    "DatasetStore",
    "FringeDataset",
    "GenerateReport",
    "VerifyReport",
    "export_fpp_ml_bench",
    "export_webdataset",
    "generate",
    "input_frame_index",
    "load_config",
]
