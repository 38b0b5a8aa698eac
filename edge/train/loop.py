"""Training with masked BCE, Adam and early stopping (paper III.E, Algorithm 1).

Differences from the paper, and why:
- From scratch by default (no ImageNet download here, and depth is not ImageNet), so the
  whole network trains and the step size is 1e-3 with cosine decay instead of 1e-5 on a frozen
  encoder; `--encoder-weights FILE --freeze-encoder --lr 1e-5` gives the paper's setting.
- Early stopping keeps the weights of the best validation loss (as the paper) and also stops
  after ``patience`` epochs without improvement, to save CPU time.
- A checkpoint is written atomically every epoch (``last.pt`` with the optimizer, ``best.pt``
  with the best weights), so ``--resume`` continues exactly where an interrupted run stopped.
- ``ema`` (optional): validation, early stopping and ``best.pt`` use an exponential moving
  average of the weights (`WeightAverage`) instead of the last step's. Why: averaged weights sit
  in flatter minima, and averaging is the cheapest known lever for domain generalisation (SWAD,
  Cha et al. 2021); the learned model's weakness is data it never saw (issue 9). No extra passes.
- ``jaccard`` (optional): adds that weight times the per-frame soft Jaccard loss
  (`edge.train.losses.soft_jaccard`) to the masked BCE, so training pulls towards the
  per-frame IoU users read. Validation loss, early stopping and the logged train loss stay
  masked BCE, comparable across runs with and without it.
- ``boundary`` (optional): pixels within 2 px of a label boundary weigh 1 + ``boundary`` in the
  masked BCE (`edge.train.losses.boundary_band`), where the model's remaining errors sit; the
  logged and validation losses stay the plain masked BCE.
- ``memory_format`` "channels_last" (the default): weights and inputs are kept channels-last
  (NHWC) on the CPU. Why: the compact models have 8-64 channels at up to full resolution, where
  oneDNN's NCHW convolutions spend most of their time reordering; NHWC made a training step
  2.2-2.3x faster on an AMD EPYC and 1.4-1.6x on an Intel Xeon (the two CPUs measured) with the
  same arithmetic (BENCHMARKS.md, "Issue 9: a training step in channels-last layout";
  `tools/train_step_bench.py`). "contiguous" is the old layout, kept to compare.
  Checkpoints are written contiguous either way, so nothing downstream sees the difference.
- ``crop`` (optional): each training frame is cut to a random (height, width) window after its
  flips (`edge.train.data.make_batch`); validation and inference see whole frames. Why: a step
  costs about what its pixels cost, so a 128 x 160 window makes steps ~2.2x faster on the 2-core
  AMD EPYC (the retraining recipe has a 60-minute budget, issue 9), and a fully convolutional
  network applies the same filters to a window as to the frame. Standardisation and the height
  cue are computed on the whole frame before the cut, as at inference. ``crop_epochs`` N: windows
  in the first N epochs only, whole frames after (progressive resizing; a model trained on
  windows throughout lost most where the frame's layout tells, at table edges, curved supports and
  trays: BENCHMARKS.md "candidate C2, results"), so the last epochs fit whole frames as inference
  sees them (Touvron et al. 2019, "Fixing the train-test resolution discrepancy").
- ``precision`` "bf16" (optional; "fp32" the default): the training forward pass runs under
  bfloat16 autocast on the CPU; weights, the optimizer, the weight average, the loss, validation
  and checkpoints stay float32. Why: on CPUs with AMX (Intel Sapphire Rapids and later) it makes a
  step ~1.4x faster (BENCHMARKS.md, "a training step in bfloat16"); elsewhere (AMD EPYC here on
  2026-12-02) it is no faster, so it is not the default.
- ``nchw_bn`` N (optional; 0 the default): with channels-last training, the batch norms over at
  most N channels normalise an NCHW copy of their input (`edge.train.layout`). Why: at full
  resolution PyTorch's channels-last CPU batch norm over 4-8 channels was 1.9-5.5x slower than
  NCHW's, ~36 % of the default model's step; N = 8 made a step x0.84-0.89 as long. Float rounding
  differs from the plain run, so the shipped recipe does not use it yet.
"""

from __future__ import annotations

import copy
import csv
import io
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from edge.errors import ConfigError, ModelError
from edge.io import atomic_write, write_bytes_atomic
from edge.meta import ModelMeta
from edge.train.checkpoint import checkpoint_meta, contiguous_state, read_checkpoint, save_checkpoint
from edge.train.data import FrameSet, PreparedSet, check_crop, make_batch
from edge.train.distributed import Dist
from edge.train.layout import nchw_batch_norms
from edge.train.losses import masked_bce
from edge.train.model import FCN8s, build_model, count_parameters, freeze_encoder, load_vgg_weights

MEMORY_FORMATS = {"channels_last": torch.channels_last, "contiguous": torch.contiguous_format}
PRECISIONS = ("fp32", "bf16")  # of the training forward pass (`TrainConfig.precision`)

__all__ = ["MEMORY_FORMATS", "PRECISIONS", "TrainConfig", "TrainResult", "WeightAverage", "train", "masked_bce", "plot_losses"]


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 100
    batch_size: int = 16
    lr: float = 1e-3
    lr_schedule: str = "cosine"
    weight_decay: float = 0.0
    patience: int = 10
    seed: int = 0
    threads: int = 2
    augment: bool = True
    max_minutes: float | None = None
    freeze_encoder: bool = False
    encoder_weights: str | None = None
    ema: float = 0.0  # decay of the weight average per step; 0 = off (the last step's weights)
    jaccard: float = 0.0  # weight of the per-frame soft Jaccard term added to masked BCE; 0 = off
    boundary: float = 0.0  # extra BCE weight of pixels within 2 px of a label boundary; 0 = off
    memory_format: str = "channels_last"  # "channels_last" (NHWC, faster on CPU) or "contiguous" (NCHW)
    precision: str = "fp32"  # of the training forward pass: "fp32" or "bf16" (autocast; faster with AMX)
    crop: tuple[int, int] | None = None  # (height, width) random training window; None = whole frames
    crop_epochs: int | None = None  # with crop: windows in the first N epochs only, whole frames after; None = all
    nchw_bn: int = 0  # channels-last only: batch norms over <= this many channels run on NCHW copies; 0 = off

    def __post_init__(self) -> None:
        if self.epochs < 1:
            raise ConfigError(f"epochs must be >= 1, got {self.epochs}")
        if self.batch_size < 1:
            raise ConfigError(f"batch size must be >= 1, got {self.batch_size}")
        if not self.lr > 0:
            raise ConfigError(f"learning rate must be > 0, got {self.lr}")
        if self.lr_schedule not in ("cosine", "constant"):
            raise ConfigError(f"lr schedule must be 'cosine' or 'constant', got '{self.lr_schedule}'")
        if not 0.0 <= self.ema < 1.0:
            raise ConfigError(f"ema decay must be in [0, 1) (0 = off, e.g. 0.999), got {self.ema}")
        if not (math.isfinite(self.jaccard) and self.jaccard >= 0):
            raise ConfigError(f"jaccard weight must be a number >= 0 (0 = off, e.g. 0.5), got {self.jaccard}")
        if not (math.isfinite(self.boundary) and 0 <= self.boundary <= 100):
            raise ConfigError(f"boundary weight must be a number in [0, 100] (0 = off, e.g. 2), got {self.boundary}")
        if self.memory_format not in MEMORY_FORMATS:
            raise ConfigError(
                f"memory format must be one of {', '.join(MEMORY_FORMATS)}, got '{self.memory_format}'"
            )
        if self.precision not in PRECISIONS:
            raise ConfigError(f"precision must be one of {', '.join(PRECISIONS)}, got '{self.precision}'")
        if self.crop is not None:
            if len(self.crop) != 2 or any(isinstance(v, bool) or not isinstance(v, int) or v < 1 for v in self.crop):
                raise ConfigError(f"crop must be (height, width) in whole pixels >= 1, e.g. (128, 160); got {self.crop}")
            if not self.augment:
                raise ConfigError("a crop window is a random augmentation: train with augmentation or without a crop")
        if self.crop_epochs is not None:
            if self.crop is None:
                raise ConfigError("crop epochs count the epochs on windows: give a crop too, e.g. (128, 160)")
            if isinstance(self.crop_epochs, bool) or not isinstance(self.crop_epochs, int) or self.crop_epochs < 0:
                raise ConfigError(f"crop epochs must be a whole number >= 0, got {self.crop_epochs}")

        if isinstance(self.nchw_bn, bool) or not isinstance(self.nchw_bn, int) or not 0 <= self.nchw_bn <= 4096:
            raise ConfigError(f"nchw batch-norm channels must be a whole number in [0, 4096] (0 = off, e.g. 8), got {self.nchw_bn}")
        if self.nchw_bn and self.memory_format != "channels_last":
            raise ConfigError("nchw batch-norm channels change channels-last training only: "
                              "train with memory format channels_last or without them")

    def autocast(self, device_type: str = "cpu") -> torch.autocast:
        """The context of a training forward pass: bfloat16 autocast for "bf16", else a no-op.

        Args:
            device_type: where the model runs ("cpu"; "cuda" under torchrun on GPUs).
        """
        return torch.autocast(device_type, dtype=torch.bfloat16, enabled=self.precision == "bf16")

    @property
    def torch_memory_format(self) -> torch.memory_format:
        return MEMORY_FORMATS[self.memory_format]


@dataclass
class TrainResult:
    best_epoch: int
    best_val_loss: float
    epochs_run: int
    history: list[dict[str, Any]] = field(default_factory=list)
    minutes: float = 0.0
    best_path: Path | None = None
    stopped: str = ""  # why training ended before cfg.epochs: "patience", "max_minutes"; "" = ran them all


class WeightAverage:
    """Exponential moving average of a model's weights and float buffers, updated after each step.

    The decay warms up as ``min(decay, (1 + n) / (10 + n))`` after ``n`` updates (timm's
    ModelEmaV2 rule), so the first steps' random weights fade quickly. Integer buffers (batch
    norm's step counter) are copied.

    Args:
        model: the trained model; the average starts as a copy of it.
        decay: per-step decay in (0, 1); 0.999 averages over ~1,000 steps.
    """

    def __init__(self, model: nn.Module, decay: float) -> None:
        self.decay = float(decay)
        self.updates = 0
        self.model = copy.deepcopy(model).eval()
        for p in self.model.parameters():
            p.requires_grad_(False)

    @torch.no_grad()
    def update(self, model: nn.Module) -> None:
        d = min(self.decay, (1 + self.updates) / (10 + self.updates))
        self.updates += 1
        for avg, cur in zip(self.model.state_dict().values(), model.state_dict().values()):
            if avg.dtype.is_floating_point:
                avg.mul_(d).add_(cur.detach(), alpha=1 - d)
            else:
                avg.copy_(cur)

    def state(self) -> dict[str, Any]:
        return {"state_dict": contiguous_state(self.model.state_dict()), "updates": self.updates}

    def load(self, state: dict[str, Any]) -> None:
        self.model.load_state_dict(state["state_dict"])
        self.updates = int(state["updates"])


def _evaluate(model: FCN8s, fs: FrameSet | PreparedSet, meta: ModelMeta, batch: int) -> tuple[float, float]:
    """(mean validation loss per valid pixel, mean per-frame object IoU at 0.5)."""
    total, count, iou_sum, n = _eval_sums(model, fs, meta, batch)
    return total / max(count, 1.0), iou_sum / n if n else float("nan")


def _eval_sums(model: FCN8s, fs: FrameSet | PreparedSet, meta: ModelMeta, batch: int,
               device: torch.device | None = None,
               memory_format: torch.memory_format = torch.contiguous_format) -> tuple[float, float, float, int]:
    """(loss sum, valid pixels, IoU sum, frames): sums, so ranks of a DDP run can add theirs.

    ``memory_format``: the layout of the model's weights (`TrainConfig.memory_format`), given to
    the inputs too so that no convolution reorders them."""
    model.eval()
    total, count, ious = 0.0, 0.0, []
    with torch.no_grad():
        for s in range(0, len(fs), batch):
            idx = np.arange(s, min(s + batch, len(fs)))
            x, t, m = (torch.from_numpy(a).to(device or "cpu") for a in make_batch(fs, idx, meta))
            logits = model(x.contiguous(memory_format=memory_format))
            loss = nn.functional.binary_cross_entropy_with_logits(logits, t, reduction="none")
            total += float((loss * m).sum())
            count += float(m.sum())
            pred = (logits > 0) & (m > 0)
            gt = (t > 0.5) & (m > 0)
            inter = (pred & gt).sum(dim=(1, 2, 3)).double()
            union = (pred | gt).sum(dim=(1, 2, 3)).double()
            ious.extend(torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union)).tolist())
    model.train()
    return total, count, float(np.sum(ious)), len(ious)


def _write_csv(path: Path, history: list[dict[str, Any]]) -> None:
    if not history:
        return
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(history[0]))
    w.writeheader()
    for row in history:
        w.writerow(row)
    write_bytes_atomic(path, buf.getvalue().encode())


def plot_losses(history: list[dict[str, Any]], batch_losses: list[float], out: Path) -> None:
    """Loss curves like the paper's Fig. 4: smoothed per-batch train loss, per-epoch val loss."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if batch_losses:
        b = np.asarray(batch_losses)
        k = min(50, len(b))
        smooth = np.convolve(b, np.ones(k) / k, mode="valid")
        ax.plot(np.arange(k, len(b) + 1), smooth, color="tab:green", label=f"train (batch, moving avg {k})")
    if history:
        its = [h["iteration"] for h in history]
        ax.plot(its, [h["val_loss"] for h in history], "o-", color="tab:red", label="validation (epoch mean)")
    ax.set_xlabel("iteration")
    ax.set_ylabel("masked BCE loss")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_write(out) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def train(
    meta: ModelMeta,
    train_set: FrameSet | PreparedSet,
    val_set: FrameSet | PreparedSet,
    out_dir: str | Path,
    cfg: TrainConfig,
    resume: bool = False,
    on_batch: Callable[[int, float], None] | None = None,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
    training_info: dict[str, Any] | None = None,
) -> TrainResult:
    out = Path(out_dir)
    if cfg.crop is not None:
        check_crop(cfg.crop, tuple(train_set.label.shape[1:]), meta.pad_multiple)  # before any work: a clear error, nothing written
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    model = build_model(meta)
    if cfg.encoder_weights:
        load_vgg_weights(model, cfg.encoder_weights)
    if cfg.freeze_encoder:
        freeze_encoder(model)
    fmt = cfg.torch_memory_format
    model = model.to(memory_format=fmt)  # before the optimizer and the weight average take its tensors
    if cfg.nchw_bn:
        nchw_batch_norms(model, cfg.nchw_bn)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=cfg.lr, betas=(0.9, 0.999), eps=1e-8, weight_decay=cfg.weight_decay)
    steps_per_epoch = math.ceil(len(train_set) / cfg.batch_size)
    avg = WeightAverage(model, cfg.ema) if cfg.ema > 0 else None

    history: list[dict[str, Any]] = []
    batch_losses: list[float] = []
    # Epochs are numbered from 1 everywhere they are shown or stored (console, log.csv, checkpoint,
    # metadata): "epoch 3" is the third pass over the data. best_epoch 0 = none yet.
    start_epoch, best_loss, best_epoch, elapsed_before = 0, float("inf"), 0, 0.0
    last = out / "last.pt"
    if resume:
        if not last.exists():
            raise ModelError(f"{last}: nothing to resume; start without `resume`")
        blob = read_checkpoint(last)
        saved = checkpoint_meta(last, blob)
        for k in ("encoder", "width", "in_channels", "batch_norm", "extra_skip", "full_skip", "standardize", "cues"):
            if getattr(saved, k) != getattr(meta, k):
                raise ConfigError(
                    f"`resume`: {k}={getattr(meta, k)!r} contradicts the checkpoint's {getattr(saved, k)!r}"
                )
        if (avg is not None) != ("weight_average" in blob):
            raise ConfigError(
                f"`resume`: ema={cfg.ema} contradicts the checkpoint, which was trained "
                f"{'with' if 'weight_average' in blob else 'without'} a weight average; resume with the run's `ema`"
            )
        try:
            model.load_state_dict(blob["state_dict"])
            opt.load_state_dict(blob["optimizer"])
            if avg is not None:
                avg.load(blob["weight_average"])
            old = blob.get("epoch_base") != 1  # checkpoints before epochs were numbered from 1
            if isinstance(blob["epoch"], bool) or not isinstance(blob["epoch"], int) or not 0 <= blob["epoch"] < 10**6:
                raise ValueError(f"epoch {blob['epoch']!r} is not a count")
            start_epoch = int(blob["epoch"]) + (1 if old else 0)  # 0-based index of the next epoch
            history = list(blob.get("history", []))
            batch_losses = [float(v) for v in blob.get("batch_losses", [])]
            best_loss = float(blob.get("best_val_loss") or float("inf"))
            best_epoch = int(blob.get("best_epoch", -1)) + (1 if old else 0)
            elapsed_before = float(blob.get("minutes", 0.0))
        except (KeyError, TypeError, ValueError, RuntimeError, OverflowError) as exc:
            raise ModelError(
                f"{last}: cannot resume from it ({type(exc).__name__}: {' '.join(str(exc).split())[:160]}); "
                "start a new run with another `out`"
            ) from None

    def lr_at(epoch: int) -> float:
        if cfg.lr_schedule == "constant":
            return cfg.lr
        return 0.5 * cfg.lr * (1 + math.cos(math.pi * epoch / cfg.epochs))

    dist = Dist.from_env()  # torchrun: DDP across ranks (edge.train.distributed); one process: no-op
    net = dist.wrap(model)
    if avg is not None:
        avg.model.to(dist.device)  # beside the model on its device (CUDA under torchrun)
    if dist.enabled:
        training_info = dict(training_info or {}, ddp_world_size=dist.world)
    t0 = time.time()
    info = dict(training_info or {})
    epoch = start_epoch  # 1-based number of the last epoch run
    stopped = ""
    for i in range(start_epoch, cfg.epochs):  # i: 0-based index (schedule and shuffling seed)
        epoch = i + 1
        if best_epoch > 0 and epoch - best_epoch > cfg.patience:
            epoch -= 1
            stopped = "patience"
            break
        te = time.time()
        for g in opt.param_groups:
            g["lr"] = lr_at(i)
        rng = np.random.default_rng([cfg.seed, i])
        order = rng.permutation(len(train_set))
        crop = cfg.crop if cfg.crop_epochs is None or i < cfg.crop_epochs else None
        model.train()
        run_loss = 0.0
        for b in range(steps_per_epoch):
            idx = order[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            x, t, m = dist.local(make_batch(train_set, idx, meta, rng if cfg.augment else None, crop=crop))
            with cfg.autocast(dist.device.type):
                logits = net(x.contiguous(memory_format=fmt))
            loss, lv = dist.loss(logits.float(), t, m, cfg.jaccard, cfg.boundary)  # in float32 whatever the forward
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if avg is not None:
                avg.update(model)
            batch_losses.append(lv)
            run_loss += lv
            if on_batch and dist.is_main:
                on_batch(b, lv)
        vset = val_set.subset(dist.shard(len(val_set))) if dist.enabled else val_set
        kept = avg.model if avg is not None else model  # the weights validated and kept as best.pt
        vs = dist.all_sum(list(_eval_sums(kept, vset, meta, cfg.batch_size, dist.device, fmt)))
        val_loss, val_iou = vs[0] / max(vs[1], 1.0), vs[2] / vs[3] if vs[3] else float("nan")
        minutes = elapsed_before + (time.time() - t0) / 60
        row = {
            "epoch": epoch,
            "iteration": len(batch_losses),
            "train_loss": run_loss / steps_per_epoch,
            "val_loss": val_loss,
            "val_iou": val_iou,
            "lr": lr_at(i),
            "epoch_seconds": round(time.time() - te, 1),
            "minutes": round(minutes, 2),
        }
        history.append(row)
        improved = val_loss < best_loss
        if improved:
            best_loss, best_epoch = val_loss, epoch
        rec = dict(info, config=asdict(cfg), best_epoch=best_epoch, best_val_loss=best_loss,
                   epochs_run=epoch, minutes=round(minutes, 2), train_frames=len(train_set),
                   val_frames=len(val_set), trainable_params=count_parameters(model, trainable_only=True))
        extra = {"weight_average": avg.state()} if avg is not None else {}
        m_meta = meta.with_(training=rec)
        if dist.is_main:  # rank 0 alone writes
            if improved:
                save_checkpoint(out / "best.pt", kept, m_meta, epoch=epoch, epoch_base=1, best_val_loss=best_loss,
                                history=history)
            save_checkpoint(last, model, m_meta, epoch=epoch, epoch_base=1, best_val_loss=best_loss,
                            best_epoch=best_epoch, history=history, optimizer=opt.state_dict(),
                            batch_losses=batch_losses, minutes=minutes, **extra)
            _write_csv(out / "log.csv", history)
            plot_losses(history, batch_losses, out / "loss.png")
            if on_epoch:
                on_epoch(row)
        if cfg.max_minutes is not None:
            per_epoch = (time.time() - t0) / 60 / (epoch - start_epoch)
            if epoch < cfg.epochs and dist.agree(minutes + per_epoch > cfg.max_minutes):
                stopped = "max_minutes"
                break
    # the final best.pt carries the complete history and the final recipe facts
    best = out / "best.pt"
    dist.close()  # waits for every rank
    if best.exists() and dist.is_main:
        blob = read_checkpoint(best)
        bm = checkpoint_meta(best, blob)
        rec = dict(bm.training, epochs_run=epoch, minutes=round(elapsed_before + (time.time() - t0) / 60, 2))
        model_b = build_model(bm)
        model_b.load_state_dict(blob["state_dict"])
        save_checkpoint(best, model_b, bm.with_(training=rec), epoch=blob["epoch"], epoch_base=1,
                        best_val_loss=best_loss, history=history)
    return TrainResult(best_epoch, best_loss, epoch, history,
                       elapsed_before + (time.time() - t0) / 60, best if best.exists() else None, stopped)
