"""Training and evaluation runs: ``virtus learn train`` and ``virtus learn eval``.

A run directory (owned by one run at a time, :func:`virtus.io.runs.claim_run`)::

    run.json          the run record (command, configuration, input checksums, status)
    config.json       the TrainConfig used, and the store trained on
    checkpoint.pt     model + optimiser + scheduler + position (epoch, batch, step) + the
                      architecture; written atomically every ``checkpoint_every`` steps
                      and at each epoch's end
    history.json      per epoch: train loss, validation loss, learning rate
    metrics.json      :mod:`virtus.learn.metrics` of the final model on the store's test
                      split (``virtus learn eval`` adds ``evaluations/<name>.json``
                      and the depth maps of its first samples, ``evaluations/<name>/``)

Determinism: the weights are initialised from ``seed``, the batches of epoch ``e`` are the
permutation ``default_rng([seed, e])`` of the training samples, and nothing else draws
random numbers (no dropout), so a run killed at any point and resumed (``resume=True``)
from its last checkpoint ends with the same weights as one uninterrupted run (bit for bit
on CPU; CUDA kernels may differ in the last bits). On CUDA with ``amp`` the network runs
under bfloat16 autocast (no loss scaling needed); the calibration layer always runs in
float64.

Phase model: the network predicts ``(sin, cos)`` of the wrapped phase of the vertical
fringes. In training the depth loss unwraps it to the true absolute phase's nearest branch
(a wrong branch would be a 2 pi gradient cliff) and triangulates it with the sample's own
:class:`~virtus.learn.triangulate.DepthLayer`. In evaluation it is unwrapped with the
sample's fringe order -- what a correct Gray-code decode gives, ``k = floor(u / T + 1/2)``
-- so a phase error at the +-pi wrap becomes an order error, as in practice for a plain Gray
code; ``evaluate(..., unwrap="decode")`` instead takes the branch nearest the absolute phase
decoded from the sample's own frames (what a complementary Gray code does with the
prediction: an order error only where the prediction is off by more than ~pi).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.io.runs import atomic_write, claim_run, file_digest, write_json_atomic
from virtus.learn._torch import require_torch
from virtus.learn.config import TrainConfig
from virtus.learn.dataset import LearnDataset
from virtus.learn.losses import hybrid_l1, masked_l1, phase_loss
from virtus.learn.metrics import MetricSums, sample_errors
from virtus.learn.models import UNet

__all__ = ["CHECKPOINT", "evaluate", "load_model", "train"]

torch = require_torch()

CHECKPOINT = "checkpoint.pt"
CHECKPOINT_FORMAT = "virtus.learn_checkpoint/1"
_LAYOUT = ("config.json", CHECKPOINT, "history.json", "metrics.json")
#: ``evaluate`` saves the depth maps of this many first samples (for the run's report),
#: each ``evaluations/<name>/sample_NNNNNN.npy``, (3, H, W) float32 mm, layers in order:
MAP_SAMPLES = 3
MAP_LAYERS = ("predicted_depth", "true_depth", "error")


def _architecture(config: TrainConfig) -> dict[str, Any]:
    out = 1 if config.model == "unet" else 2
    return {
        "net": "unet",
        "model": config.model,
        "in_channels": 1,
        "out_channels": out,
        "base_channels": config.base_channels,
        "levels": config.levels,
    }


def build_model(config: TrainConfig) -> Any:
    arch = _architecture(config)
    return UNet(arch["in_channels"], arch["out_channels"], config.base_channels, config.levels)


class _Runner:
    """Forward passes and losses of one model on one device (layers cached per rig)."""

    def __init__(self, config: TrainConfig, model: Any, device: Any) -> None:
        self.config, self.model, self.device = config, model, device
        self.layers: dict[int, Any] = {}
        self.amp = bool(config.amp and device.type == "cuda")
        #: Evaluation's fringe orders: "label" (the stored order: a perfect Gray-code decode)
        #: or "decode" (decoded from the sample's own frames, code errors included).
        self.unwrap = "label"

    def _net(self, image: Any) -> Any:
        with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.amp):
            return self.model(image.to(self.device)).float()

    def _layer(self, dataset: LearnDataset, item: int) -> tuple[Any, float]:
        layer, period = dataset.layer(item)
        key = id(layer)
        if key not in self.layers:
            self.layers[key] = layer.to(self.device)
        return self.layers[key], period

    def phase_depth(self, dataset: LearnDataset, items: list[int], absolute: Any) -> Any:
        """Depth (m, float32) of absolute phases ``(B, H, W)`` with each sample's layer
        (samples sharing a rig and period go through their layer together: one call)."""
        from virtus.learn.triangulate import phase_to_coordinate

        groups: dict[tuple[int, float], tuple[Any, float, list[int]]] = {}
        for b, item in enumerate(items):
            layer, period = self._layer(dataset, item)
            groups.setdefault((id(layer), period), (layer, period, []))[2].append(b)
        out: list[Any] = [None] * len(items)
        for layer, period, members in groups.values():
            index = torch.tensor(members, device=absolute.device)
            depth = layer.depth(phase_to_coordinate(absolute[index].double(), period)).float()
            for j, b in enumerate(members):
                out[b] = depth[j]
        return torch.stack(out)

    def loss(self, dataset: LearnDataset, items: list[int], batch: dict[str, Any]) -> Any:
        c = self.config
        b = {k: v.to(self.device) for k, v in batch.items() if torch.is_tensor(v)}
        out = self._net(b["image"])
        if c.model == "unet":
            target = (b["depth"] - c.depth_offset_m) / c.depth_range_m
            return hybrid_l1(out[:, 0], target, b["object"], b["surface"], c.alpha)
        sin_cos = out
        loss = phase_loss(sin_cos, b["wrapped"], b["valid"])
        if c.depth_weight > 0:
            wrapped = torch.atan2(sin_cos[:, 0], sin_cos[:, 1])
            true_abs = b["wrapped"] + 2 * np.pi * b["order"].clamp(min=0)
            step = torch.remainder(wrapped - b["wrapped"] + np.pi, 2 * np.pi) - np.pi
            depth = self.phase_depth(dataset, items, true_abs + step)
            ok = b["valid"] & torch.isfinite(depth)
            depth = torch.where(ok, depth, b["depth"])
            loss = loss + c.depth_weight * masked_l1(
                depth / c.depth_range_m, b["depth"] / c.depth_range_m, ok
            )
        return loss

    @torch.no_grad()
    def predict(
        self, dataset: LearnDataset, item: int, sample: dict[str, Any]
    ) -> dict[str, np.ndarray]:
        """Depth (m, NaN where none) and, for the phase model, wrapped phase and order, of
        ``sample = dataset[item]``."""
        c = self.config
        out = self._net(sample["image"][None])[0]
        if c.model == "unet":
            return {"depth": (out[0] * c.depth_range_m + c.depth_offset_m).cpu().numpy()}
        wrapped = torch.atan2(out[0], out[1])
        true_order = sample["order"].to(self.device)
        true_abs = sample["wrapped"].to(self.device) + 2 * np.pi * true_order.clamp(min=0)
        if self.unwrap == "decode":  # the branch nearest the sample's own decode
            decoded = torch.from_numpy(dataset.decoded_phase(item)).to(self.device)
            ok = torch.isfinite(decoded)
            decoded = torch.where(ok, decoded, torch.zeros_like(decoded)).float()
            absolute = decoded + torch.remainder(wrapped - decoded + np.pi, 2 * np.pi) - np.pi
        else:  # the stored order: a perfect Gray-code decode, floor(u / T + 1/2)
            ok = true_order >= 0
            absolute = wrapped + 2 * np.pi * true_order.clamp(min=0)
        depth = self.phase_depth(dataset, [item], absolute[None])[0]
        depth = torch.where(ok, depth, torch.full_like(depth, float("nan")))
        pred_order = true_order + torch.round((absolute - true_abs) / (2 * np.pi)).long()
        return {
            "depth": depth.cpu().numpy(),
            "wrapped": wrapped.cpu().numpy(),
            "order": pred_order.cpu().numpy(),
        }


def _evaluate_set(
    runner: _Runner, dataset: LearnDataset, maps: list[tuple[int, np.ndarray]] | None = None
) -> dict[str, Any]:
    """Metrics of the model over ``dataset``; with ``maps``, the first :data:`MAP_SAMPLES`
    samples' ``(index, (3, H, W) float32 [predicted, true, predicted - true] depth, mm)``
    are appended to it (NaN: no surface or no prediction)."""
    runner.model.eval()
    sums = MetricSums()
    for item in range(len(dataset)):
        sample = dataset[item]
        pred = runner.predict(dataset, item, sample)
        if maps is not None and item < MAP_SAMPLES:
            maps.append((int(sample["index"]), _depth_maps(pred["depth"], sample)))
        layer, _ = dataset.layer(item)
        extra: dict[str, Any] = {"rays": layer.rays.cpu().numpy()}
        if "wrapped" in pred:
            extra.update(
                pred_wrapped=pred["wrapped"],
                wrapped=sample["wrapped"].numpy(),
                pred_order=pred["order"],
                order=sample["order"].numpy(),
                valid=sample["valid"].numpy(),
            )
        sums.add(
            sample_errors(
                pred["depth"],
                sample["depth"].numpy(),
                sample["surface"].numpy(),
                sample["object"].numpy(),
                **extra,
            )
        )
    return sums.summary()


def _depth_maps(predicted_m: np.ndarray, sample: dict[str, Any]) -> np.ndarray:
    """``(3, H, W)`` float32 mm: predicted, true and error depth on the surface pixels."""
    surface = sample["surface"].numpy().astype(bool)
    true = np.where(surface, sample["depth"].numpy().astype(np.float64), np.nan)
    pred = np.where(surface, np.asarray(predicted_m, dtype=np.float64), np.nan)
    return (np.stack([pred, true, pred - true]) * 1e3).astype(np.float32)


def _batches(n: int, config: TrainConfig, epoch: int) -> list[list[int]]:
    order = np.random.default_rng([config.seed, epoch]).permutation(n)
    return [order[i : i + config.batch_size].tolist() for i in range(0, n, config.batch_size)]


def _collate(dataset: LearnDataset, items: list[int]) -> dict[str, Any]:
    samples = [dataset[i] for i in items]
    return {k: torch.stack([s[k] for s in samples]) for k in samples[0] if k != "index"}


def _loader(dataset: LearnDataset, batches: list[list[int]], workers: int) -> Any:
    """``(items, batch)`` pairs in the given order; read by ``workers`` processes (0: here).
    The order is fixed by ``batches`` whatever the worker count, so runs stay comparable."""
    if workers == 0:
        return ((items, _collate(dataset, items)) for items in batches)
    from torch.utils.data import DataLoader

    loader = DataLoader(
        _Batches(dataset, batches), batch_size=None, num_workers=workers,
        pin_memory=torch.cuda.is_available(),
        prefetch_factor=4, persistent_workers=False,
    )  # fmt: skip
    return zip(batches, loader, strict=True)


class _Batches:
    """A map-style dataset of whole batches (a worker reads and stacks one batch)."""

    def __init__(self, dataset: LearnDataset, batches: list[list[int]]) -> None:
        self.dataset, self.batches = dataset, batches

    def __len__(self) -> int:
        return len(self.batches)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return _collate(self.dataset, self.batches[i])


def _save(run: Any, state: dict[str, Any]) -> None:
    run.write(CHECKPOINT, lambda path: torch.save(state, path))


def _device(device: str | None) -> Any:
    if device is None:
        device = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(device)


def train(
    config: TrainConfig,
    store: str | Path,
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    device: str | None = None,
    on_step: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Train ``config``'s model on the store's ``train`` split into the run directory ``out``
    (module docstring); returns the test metrics (also in ``metrics.json``).

    ``on_step(step)`` is called after every optimiser step (progress; tests raise from it
    to kill a run at a chosen step). ``resume`` continues from ``checkpoint.pt``.
    """
    store = Path(store)
    c = config
    train_set = LearnDataset(store, "train", c.model, c.input_frame, c.direction)
    if len(train_set) == 0:
        raise InputError("store", "a store with samples in its train split", "none")
    splits = train_set.base.splits
    val_set, test_set = (
        LearnDataset(store, split, c.model, c.input_frame, c.direction) if split in splits else None
        for split in ("val", "test")
    )
    dev = _device(device)
    setting = {"train": config.to_dict(), "store": str(store.resolve())}
    with claim_run(
        out,
        "learn train",
        setting,
        inputs={"dataset": store / "dataset.json"},
        layout=_LAYOUT,
        resume=resume,
        overwrite=overwrite,
    ) as run:
        torch.manual_seed(config.seed)
        if dev.type == "cpu":
            torch.use_deterministic_algorithms(True)
        model = build_model(config).to(dev)
        optimiser = torch.optim.RMSprop(
            model.parameters(), lr=config.lr, weight_decay=config.weight_decay
        )
        scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
            optimiser, factor=0.1, patience=config.plateau_patience
        )
        state = {"epoch": 0, "batch": 0, "step": 0, "history": []}
        if run.resumed and run.file(CHECKPOINT).is_file():
            saved = torch.load(run.file(CHECKPOINT), map_location=dev, weights_only=False)
            model.load_state_dict(saved["model"])
            optimiser.load_state_dict(saved["optimiser"])
            scheduler.load_state_dict(saved["scheduler"])
            state = saved["state"]
        run.write_json("config.json", {**setting, "architecture": _architecture(config)})
        runner = _Runner(config, model, dev)

        def checkpoint() -> None:
            _save(
                run,
                {
                    "format": CHECKPOINT_FORMAT,
                    "architecture": _architecture(config),
                    "config": config.to_dict(),
                    "model": model.state_dict(),
                    "optimiser": optimiser.state_dict(),
                    "scheduler": scheduler.state_dict(),
                    "state": state,
                },
            )

        _fit(runner, optimiser, scheduler, train_set, val_set, state, checkpoint, on_step)
        run.write_json("history.json", state["history"])
        metrics = {
            "test": _evaluate_set(runner, test_set) if test_set is not None else None,
            "steps": state["step"],
            "architecture": _architecture(config),
        }
        run.write_json("metrics.json", metrics)
    return metrics


def _fit(
    runner: _Runner,
    optimiser: Any,
    scheduler: Any,
    train_set: LearnDataset,
    val_set: LearnDataset | None,
    state: dict[str, Any],
    checkpoint: Callable[[], None],
    on_step: Callable[[int], None] | None,
) -> None:
    """Epochs from ``state`` (epoch, batch, step) on; updates ``state`` and checkpoints."""
    config, model = runner.config, runner.model
    done = config.max_steps is not None and state["step"] >= config.max_steps
    while state["epoch"] < config.epochs and not done:
        batches = _batches(len(train_set), config, state["epoch"])
        model.train()
        losses: list[float] = state.setdefault("losses", [])
        for items, batch in _loader(train_set, batches[state["batch"] :], config.workers):
            optimiser.zero_grad(set_to_none=True)
            loss = runner.loss(train_set, items, batch)
            loss.backward()
            optimiser.step()
            losses.append(float(loss.detach()))
            state["batch"] += 1
            state["step"] += 1
            if state["step"] % config.checkpoint_every == 0:
                checkpoint()
            if on_step is not None:
                on_step(state["step"])
            if config.max_steps is not None and state["step"] >= config.max_steps:
                done = True
                break
        if state["batch"] < len(batches):  # stopped by max_steps inside the epoch
            checkpoint()
            break
        val_loss = _validation_loss(runner, val_set) if val_set is not None else None
        if val_loss is not None:
            scheduler.step(val_loss)
        state["history"].append(
            {
                "epoch": state["epoch"],
                "train_loss": float(np.mean(losses)),
                "val_loss": val_loss,
                "lr": optimiser.param_groups[0]["lr"],
                "steps": state["step"],
            }
        )
        state.update(epoch=state["epoch"] + 1, batch=0, losses=[])
        checkpoint()


@torch.no_grad()
def _validation_loss(runner: _Runner, dataset: LearnDataset) -> float | None:
    if len(dataset) == 0:
        return None
    runner.model.eval()
    total = [float(runner.loss(dataset, [i], _collate(dataset, [i]))) for i in range(len(dataset))]
    runner.model.train()
    return float(np.mean(total))


def load_model(run_dir: str | Path, device: str | None = None) -> tuple[TrainConfig, Any]:
    """The configuration and trained model of a run directory.

    Raises
    ------
    InputError : no checkpoint, a file that is not a virtus.learn checkpoint, or weights
        that do not fit the architecture the checkpoint names (another architecture).
    """
    path = Path(run_dir) / CHECKPOINT
    if not path.is_file():
        raise InputError("run", f"a run directory with {CHECKPOINT}", str(run_dir))
    try:
        saved = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as error:  # torch raises many kinds for a damaged or foreign file
        raise InputError(
            "checkpoint", "a virtus.learn checkpoint", f"unreadable ({error})"
        ) from None
    if not isinstance(saved, dict) or saved.get("format") != CHECKPOINT_FORMAT:
        raise InputError("checkpoint", f"a {CHECKPOINT_FORMAT} file", str(path))
    config = TrainConfig.from_dict(saved["config"])
    if saved.get("architecture") != _architecture(config):
        raise InputError(
            "checkpoint", f"architecture {_architecture(config)}", saved.get("architecture")
        )
    model = build_model(config)
    try:
        model.load_state_dict(saved["model"])
    except RuntimeError as error:
        first = str(error).strip().splitlines()[0]
        raise InputError(
            "checkpoint",
            f"weights of a {config.model} UNet {_architecture(config)}",
            f"weights of another architecture ({first})",
        ) from None
    return config, model.to(_device(device))


def evaluate(
    run_dir: str | Path,
    store: str | Path,
    split: str | None = "test",
    *,
    device: str | None = None,
    name: str | None = None,
    unwrap: str = "label",
) -> dict[str, Any]:
    """Metrics of a run's model on a store's ``split`` (None: all samples), written to
    ``RUN/evaluations/<name>.json`` (default name: the store folder's, the split's and, for
    ``unwrap="decode"``, ``-decode``). ``unwrap``: how a phase model is unwrapped, ``"label"``
    (the stored order) or ``"decode"`` (decoded from each sample's own frames)."""
    if unwrap not in ("label", "decode"):
        raise InputError("unwrap", "'label' or 'decode'", unwrap)
    config, model = load_model(run_dir, device)
    dataset = LearnDataset(store, split, config.model, config.input_frame, config.direction)
    runner = _Runner(config, model, next(model.parameters()).device)
    runner.unwrap = unwrap
    maps: list[tuple[int, np.ndarray]] = []
    summary = {
        "store": str(Path(store).resolve()),
        "split": split,
        "unwrap": unwrap,
        **_evaluate_set(runner, dataset, maps),
    }
    label = name or f"{Path(store).name}-{split or 'all'}" + (
        "-decode" if unwrap == "decode" else ""
    )
    summary["maps"] = write_maps(Path(run_dir) / "evaluations", label, maps)
    write_json_atomic(Path(run_dir) / "evaluations" / f"{label}.json", summary)
    return summary


def write_maps(folder: Path, label: str, maps: list[tuple[int, np.ndarray]]) -> list[dict]:
    """Save each ``(index, maps)`` (index: a store's sample, or a capture's position in the list)
    as ``folder/label/sample_NNNNNN.npy`` (written atomically);
    the entries (file relative to ``folder``, sample index, sha256) for the summary."""
    entries = []
    for index, values in maps:
        relative = f"{label}/sample_{index:06d}.npy"
        target = folder / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(target, lambda tmp, v=values: np.save(tmp, v))
        entries.append({"file": relative, "sample": index, "sha256": file_digest(target),
                        "layers": list(MAP_LAYERS), "unit": "mm"})  # fmt: skip
    return entries
