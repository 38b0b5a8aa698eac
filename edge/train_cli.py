"""``depthseg-train``: fit an FCN-8s on simulated MCAP frames (paper Algorithm 1)."""

from __future__ import annotations

import argparse
import shlex
import sys

from edge.cliutil import add_version, print_json, progress, run
from edge.errors import ConfigError

PROG = "depthseg-train"

EPILOG = """\
examples:
  depthseg-sim --out data/train --frames 5000 --seed 1
  depthseg-train --data data/train --out runs/small --encoder vgg11 --batch-norm --width 0.125
  depthseg-train --data data/train --out runs/small --resume          # continue an interrupted run
  depthseg-train --train-dir a/ --val-dir b/ --encoder vgg16 --encoder-weights vgg16.pth \\
      --freeze-encoder --lr 1e-5 --lr-schedule constant              # the paper's setting

Data-parallel on N processes (DDP: gloo on CPU, NCCL with CUDA; --batch-size stays the global batch;
rank 0 alone writes OUT/; --resume works the same way):
  torchrun --nproc-per-node 2 -m edge.train_cli --data data/train --out runs/ddp --threads 1 ...

The best weights (lowest validation loss) are in OUT/best.pt; OUT/last.pt is the resumable
state; OUT/log.csv and OUT/loss.png show the curves (like the paper's Fig. 4).
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Train the FCN-8s segmentation model on labelled depth frames (masked BCE, Adam, early stopping).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_version(p, PROG)
    d = p.add_argument_group("data")
    d.add_argument("--data", nargs="+", help="recordings (.mcap, .bag, .db3, bag directories) or directories of them, split train/val/test by --split")
    d.add_argument("--train-dir", nargs="+", help="explicit training recordings (.mcap, .bag, .db3, bag directories) or directories of them")
    d.add_argument("--val-dir", nargs="+", help="explicit validation recordings or directories of them")
    d.add_argument("--split", default="0.7,0.2,0.1", help="train,val,test fractions for --data (default: %(default)s, the paper's)")
    d.add_argument("--split-unit", choices=("scene", "frame"), default="scene",
                   help="what --split deals out: whole simulated scenes, so that no view of a validation scene is "
                        "trained on (default), or single frames (the recipe of every shipped default up to v12)")
    d.add_argument("--limit", type=int, help="use at most this many frames (quick experiments)")
    d.add_argument("--depth-topic", default=None, help="depth Image topic (default: auto-detected, as depthseg-eval)")
    d.add_argument("--labels-topic", default=None,
                   help="label Image topic, mono8 nonzero = object (default: auto-detected); labels pair with depth "
                        "frames by header stamp within 1 ms, as in depthseg-eval")
    m = p.add_argument_group("model")
    m.add_argument("--encoder", default="vgg16", help="vgg11, vgg13, vgg16 or vgg19 (default: %(default)s, the paper's)")
    m.add_argument("--width", type=float, default=1.0, help="channel width multiplier (1.0 = paper; 0.125 = the shipped default)")
    m.add_argument("--batch-norm", action="store_true", help="batch norm after each encoder conv (helps from scratch; folded away in ONNX)")
    m.add_argument("--in-channels", type=int, default=3, choices=(1, 3), help="3 = depth replicated (paper); 1 = single channel")
    m.add_argument("--standardize", default="valid-pixels", choices=("valid-pixels", "robust"),
                   help="depth standardisation: mean/std of all valid pixels (paper) or trimmed 1-99 %% and "
                        "clipped (robust to a few far or saturated pixels)")
    m.add_argument("--cues", default="", help="extra input channels, comma-separated: 'height' = cm above the "
                   "dominant plane, 'steepness' = 1 - cos of the surface's angle to the optical axis "
                   "(edge.cues); default none")
    m.add_argument("--extra-skip", action="store_true", help="also fuse pool2 and pool1 (paper V.d)")
    m.add_argument("--full-skip", action="store_true",
                   help="also fuse the full-resolution conv1 map before the classifier (sharper object boundaries)")
    m.add_argument("--encoder-weights", help="local torchvision VGG state_dict file (ImageNet weights); default: from scratch")
    m.add_argument("--freeze-encoder", action="store_true", help="train only the decoder (the paper's setting with pretrained weights)")
    t = p.add_argument_group("training")
    t.add_argument("--out", required=True, help="run directory (checkpoints, log.csv, loss.png)")
    t.add_argument("--epochs", type=int, default=100)
    t.add_argument("--batch-size", type=int, default=16)
    t.add_argument("--lr", type=float, default=1e-3, help="Adam step size (default %(default)s from scratch; paper 1e-5 frozen)")
    t.add_argument("--lr-schedule", default="cosine", choices=("cosine", "constant"))
    t.add_argument("--ema", type=float, default=0.0, metavar="DECAY",
                   help="validate and keep an exponential moving average of the weights with this decay per step "
                   "(e.g. 0.999, ~1,000 steps; default 0 = the last step's weights)")
    t.add_argument("--jaccard", type=float, default=0.0, metavar="WEIGHT",
                   help="add WEIGHT x (1 - soft IoU of the object class, per frame) to the masked BCE, towards "
                   "the per-frame IoU that eval reports (e.g. 0.5; default 0 = BCE alone)")
    t.add_argument("--boundary-weight", type=float, default=0.0, metavar="WEIGHT",
                   help="pixels within 2 px of a label boundary weigh 1 + WEIGHT in the masked BCE, where the "
                   "model's errors sit (e.g. 2; default 0 = every pixel alike)")
    t.add_argument("--patience", type=int, default=10, help="stop after this many epochs without a better val loss")
    t.add_argument("--max-minutes", type=float, help="stop before this wall-clock budget would be exceeded")
    t.add_argument("--no-augment", action="store_true", help="disable flips (and --crop)")
    t.add_argument("--crop", metavar="HxW",
                   help="train on a random HxW window of each frame after its flips, e.g. 128x160 (~2.2x faster "
                   "steps on 2 cores; standardisation and cues still see the whole frame; validation uses whole "
                   "frames); default: whole frames")
    t.add_argument("--crop-epochs", type=int, metavar="N",
                   help="with --crop: windows in the first N epochs only, whole frames after, so the last epochs "
                   "fit the frame as inference sees it (default: windows in every epoch)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=2, help="torch intra-op threads per process (default %(default)s; "
                   "under torchrun give each process its share of the cores)")
    t.add_argument("--memory-format", default="channels_last", choices=("channels_last", "contiguous"),
                   help="layout of weights and inputs while training (default %(default)s: NHWC, 1.4-2.3x faster "
                   "steps on the CPUs measured; checkpoints are stored in the usual layout either way)")
    t.add_argument("--nchw-bn-channels", type=int, default=0, metavar="N",
                   help="with channels_last: batch norms over at most N channels normalise an NCHW copy of their "
                   "input (N=8: steps x0.84-0.89 as long on a 2-core AMD EPYC; the weights differ from a plain run by "
                   "float rounding); default %(default)s = off")
    t.add_argument("--precision", default="fp32", choices=("fp32", "bf16"),
                   help="of the training forward pass (default %(default)s); bf16 = bfloat16 autocast, ~1.4x faster "
                   "steps on CPUs with AMX (Intel Sapphire Rapids+), no faster elsewhere; weights, loss, "
                   "validation and checkpoints stay float32")
    t.add_argument("--preprocess", default="once", choices=("once", "per-batch"),  # edge.train.data.PREPROCESS_MODES
                   help="preprocess every frame once before the first epoch and flip the result (default "
                   "%(default)s: 4-13 %% faster epochs, 2x the memory of the loaded frames; per batch when that "
                   "would not fit), or the raw frames per batch in every epoch (the recipe of every shipped "
                   "default up to v12; less memory)")
    t.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    return p


def check_paths(args: argparse.Namespace) -> None:
    """Inputs readable (no FIFO), the run directory never an input nor inside one (`edge.io.paths`)."""
    from pathlib import Path

    from edge.io.paths import check_input_file, check_output_dir

    inputs = {}
    for name in ("data", "train_dir", "val_dir"):
        paths = getattr(args, name) or []
        for p in paths:
            check_input_file(p, name, allow_dir=True)
        inputs[name] = paths
    if args.encoder_weights is not None:
        inputs["encoder_weights"] = check_input_file(args.encoder_weights, "encoder_weights")
    check_output_dir(args.out, "out", inputs, probes=("best.pt", "last.pt", "log.csv", "loss.png"))
    last = Path(args.out) / "last.pt"
    if args.resume and last.exists():
        check_input_file(last, "resume")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    def body() -> int:
        check_paths(args)
        from edge.cliutil import require

        require("train", ("torch", "matplotlib"), "training")
        from edge.meta import ModelMeta
        from edge.train.data import (
            check_crop,
            data_identity,
            load_frames,
            parse_crop,
            prepare_frames,
            preprocess_mode,
            split_indices,
        )
        from edge.train.loop import TrainConfig, train

        if bool(args.data) == bool(args.train_dir):
            raise ConfigError("give either --data (split automatically) or --train-dir with --val-dir")
        if args.train_dir and not args.val_dir:
            raise ConfigError("--train-dir needs --val-dir (validation frames for early stopping)")
        try:
            fr = tuple(float(v) for v in args.split.split(","))
        except ValueError:
            fr = ()
        if len(fr) != 3 or any(v < 0 for v in fr) or abs(sum(fr) - 1) > 1e-6:
            raise ConfigError(f"--split must be three fractions summing to 1, e.g. 0.7,0.2,0.1; got '{args.split}'")
        cfg = TrainConfig(
            epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, lr_schedule=args.lr_schedule,
            patience=args.patience, seed=args.seed, threads=args.threads, augment=not args.no_augment,
            max_minutes=args.max_minutes, freeze_encoder=args.freeze_encoder, encoder_weights=args.encoder_weights,
            ema=args.ema, jaccard=args.jaccard, boundary=args.boundary_weight, memory_format=args.memory_format,
            precision=args.precision, crop=parse_crop(args.crop), crop_epochs=args.crop_epochs,
            nchw_bn=args.nchw_bn_channels,
        )
        from edge.train.encoders import list_encoders

        if args.encoder not in list_encoders():
            raise ConfigError(f"unknown encoder '{args.encoder}'; valid encoders: {', '.join(list_encoders())}")
        cues = tuple(c.strip() for c in args.cues.split(",") if c.strip())
        from edge.cues import CUES

        bad = [c for c in cues if c not in CUES]
        if bad:
            raise ConfigError(f"--cues: unknown {bad}; choose from {list(CUES)}")
        meta = ModelMeta(encoder=args.encoder, width=args.width, in_channels=args.in_channels,
                         batch_norm=args.batch_norm, extra_skip=args.extra_skip, full_skip=args.full_skip,
                         standardize=args.standardize,
                         cues=cues)
        topics = {"depth_topic": args.depth_topic, "labels_topic": args.labels_topic}
        from edge.train.distributed import Dist, is_main_process, local_world_size

        main_rank = is_main_process()  # under torchrun only rank 0 prints (edge.train.distributed)
        quiet = None if main_rank else True
        with progress(desc="loading frames", unit="frame", disable=quiet) as bar:
            if args.data:
                allf = load_frames(args.data, limit=args.limit, progress=bar, **topics)
                tr, va, _te = split_indices(len(allf), fr, args.seed, allf.scene if args.split_unit == "scene" else None)
                sources = [(allf, tr), (allf, va)]
                del allf
            else:
                sources = [(load_frames(args.train_dir, limit=args.limit, progress=bar, **topics), None),
                           (load_frames(args.val_dir, progress=bar, **topics), None)]
        if cfg.crop is not None:  # before minutes of preprocessing
            check_crop(cfg.crop, tuple(sources[0][0].depth.shape[1:]), meta.pad_multiple)
        total = sum(len(fs) if idx is None else len(idx) for fs, idx in sources)
        # Under torchrun every rank prepares the whole set: the check counts this machine's ranks,
        # runs once all of them have loaded, and any rank short of memory moves all to per-batch.
        ddp = Dist.from_env()
        ddp.all_sum([0.0])  # a barrier: every rank has its frames loaded before memory is read
        mode, why = preprocess_mode(args.preprocess, total, *sources[0][0].depth.shape[1:], len(cues),
                                    copies=local_world_size())
        if not ddp.all_agree(mode == args.preprocess):
            mode, why = "per-batch", why or "another rank's machine lacks the memory to preprocess once; preprocessing per batch"
        if why and main_rank:
            print(f"{PROG}: {why}", file=sys.stderr)
        if mode == "once":  # by index from the loaded frames: no copy of the raw split is made
            with progress(total=total, desc="preprocessing", unit="frame", disable=quiet) as bar:
                train_set, val_set = [prepare_frames(fs, meta, idx, progress=bar) for fs, idx in sources]
        else:
            train_set, val_set = [fs if idx is None else fs.subset(idx) for fs, idx in sources]
        del sources  # the raw frames, once the sets are made
        info = {
            "command": " ".join([PROG] + [shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:])]),
            "data": [str(p) for p in (args.data or args.train_dir)],
            "data_identity": data_identity(args.data or args.train_dir),
            "split_unit": args.split_unit if args.data else None,
            "input": ("Z depth replicated to 3 channels" if args.in_channels == 3 else "Z depth, 1 channel")
            + (f" + cues {list(cues)}" if cues else "") + f"; standardize={args.standardize}",
            "init": args.encoder_weights or "from scratch (Kaiming, PyTorch default)",
            "preprocess": mode,
        }
        steps = -(-len(train_set) // cfg.batch_size)
        bar = progress(total=steps, desc="epoch", unit="batch", disable=quiet)

        def on_batch(b: int, loss: float) -> None:
            bar.update(1)
            bar.set_postfix(loss=f"{loss:.4f}")

        def on_epoch(row: dict) -> None:
            bar.reset()
            bar.set_description(f"epoch {row['epoch']}")
            print(f"epoch {row['epoch']:3d}  train {row['train_loss']:.4f}  val {row['val_loss']:.4f}  "
                  f"val IoU {row['val_iou']:.4f}  lr {row['lr']:.2e}  {row['epoch_seconds']:.0f}s", file=sys.stderr, flush=True)

        try:  # the group opened above is this command's to close (train() joins it, `Dist.from_env`)
            res = train(meta, train_set, val_set, args.out, cfg, resume=args.resume, on_batch=on_batch,
                        on_epoch=on_epoch, training_info=info)
        finally:
            ddp.close()
        bar.close()
        summary = {
            "best_epoch": res.best_epoch, "best_val_loss": res.best_val_loss, "epochs_run": res.epochs_run,
            "minutes": round(res.minutes, 2), "best": str(res.best_path), "train_frames": len(train_set),
            "val_frames": len(val_set),
            "val_iou": next((h["val_iou"] for h in res.history if h["epoch"] == res.best_epoch), None),
            "stopped": res.stopped or None,
        }
        if not main_rank:
            return 0
        if args.json:
            print_json(summary)
        else:
            print(f"best epoch {summary['best_epoch']} (val loss {res.best_val_loss:.4f}, val IoU "
                  f"{summary['val_iou']:.4f}) after {res.epochs_run} epochs, {res.minutes:.1f} min -> {res.best_path}")
        if res.stopped == "max_minutes":  # a shorter run than asked for: say so, and how to finish it
            print(f"stopped after epoch {res.epochs_run} of {cfg.epochs}: another epoch would pass --max-minutes "
                  f"{cfg.max_minutes:g}; to finish, rerun with --resume and a larger --max-minutes", file=sys.stderr)
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    raise SystemExit(main())
