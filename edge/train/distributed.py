"""Data-parallel training under ``torchrun`` (DDP: gloo on CPU, NCCL when CUDA is present).

``torchrun --nproc-per-node N depthseg-train ...`` starts N processes with ``RANK``,
``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR`` and ``MASTER_PORT`` set; without them (a plain
``depthseg-train``) everything here is a no-op and training is the single process it always was.

What stays the same as one process, and why:
- ``--batch-size`` is the global batch: every rank draws the same permutation and the same
  flips (same seed), preprocesses the whole global batch and keeps its slice ``[rank::N]``, so
  the samples, the learning rate and the schedule do not depend on N.
- The loss is the masked mean over the valid pixels of the *global* batch: each rank divides
  its pixel-loss sum by the all-reduced pixel count (times N, since DDP averages gradients), so
  the gradient equals the one-process gradient up to float rounding and batch-norm statistics
  (computed per rank over its slice; running statistics are broadcast from rank 0).
- The optional soft Jaccard term (``--jaccard``) is a mean over the frames of the global batch:
  each rank scales its frames' sum by N over the all-reduced frame count.
- Validation is split across ranks and its sums all-reduced: every rank sees the same loss, so
  early stopping, patience and the "best" choice agree on all ranks.
- Rank 0 alone writes checkpoints, ``log.csv``, ``loss.png`` and prints; ``--resume`` makes every
  rank load the same ``last.pt`` (the run folder must be shared when nodes differ).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch

from edge.train.losses import boundary_band, soft_jaccard

__all__ = ["Dist", "env_world", "is_main_process", "local_world_size"]


def env_world() -> tuple[int, int, int]:
    """(rank, world size, local rank) from the torchrun environment; (0, 1, 0) without it."""
    return int(os.environ.get("RANK", 0)), int(os.environ.get("WORLD_SIZE", 1)), int(os.environ.get("LOCAL_RANK", 0))


def is_main_process() -> bool:
    return env_world()[0] == 0


def local_world_size() -> int:
    """Processes of this run on this machine (torchrun's ``LOCAL_WORLD_SIZE``); 1 without torchrun."""
    return max(int(os.environ.get("LOCAL_WORLD_SIZE", 1)), 1)


@dataclass
class Dist:
    rank: int = 0
    world: int = 1
    device: torch.device = torch.device("cpu")
    owns_group: bool = False

    @classmethod
    def from_env(cls) -> Dist:
        """Join the torchrun process group (gloo on CPU, NCCL with CUDA); one process: no-op."""
        rank, world, local = env_world()
        if world <= 1:
            return cls()
        import torch.distributed as dist

        cuda = torch.cuda.is_available()
        device = torch.device("cuda", local) if cuda else torch.device("cpu")
        if cuda:
            torch.cuda.set_device(device)
        owns = False
        if not dist.is_initialized():
            dist.init_process_group(backend="nccl" if cuda else "gloo")
            owns = True
        return cls(rank=dist.get_rank(), world=dist.get_world_size(), device=device, owns_group=owns)

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def enabled(self) -> bool:
        return self.world > 1

    def wrap(self, model: torch.nn.Module) -> torch.nn.Module:
        """``model`` on this rank's device, wrapped in DDP when there are several ranks."""
        model.to(self.device)
        if not self.enabled:
            return model
        from torch.nn.parallel import DistributedDataParallel as DDP

        ids = [self.device.index] if self.device.type == "cuda" else None
        return DDP(model, device_ids=ids)

    def local(self, arrays: tuple[np.ndarray, ...]) -> tuple[torch.Tensor, ...]:
        """This rank's slice ``[rank::world]`` of a global batch, as tensors on its device."""
        return tuple(torch.from_numpy(np.ascontiguousarray(a[self.rank :: self.world])).to(self.device) for a in arrays)

    def loss(self, logits: torch.Tensor, target: torch.Tensor, mask: torch.Tensor,
             jaccard: float = 0.0, boundary: float = 0.0) -> tuple[torch.Tensor, float]:
        """(loss to back-propagate, masked BCE of the global batch for the log).

        Args:
            logits, target, mask: this rank's slice of the batch, [b, 1, H, W] each.
            jaccard: weight of the per-frame soft Jaccard term (`soft_jaccard`), averaged over the
                frames of the global batch; 0 = masked BCE alone.
            boundary: extra weight of the pixels near label boundaries (`boundary_band`): the BCE
                becomes a weighted mean with weight 1 + ``boundary`` there, 1 elsewhere; 0 = off.
                The logged value stays the plain masked BCE.
        """
        pix = torch.nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none")
        local_sum, local_n = (pix * mask).sum(), mask.sum()
        jac = soft_jaccard(logits, target, mask).sum() if jaccard > 0 else None
        wmask = mask * (1.0 + boundary * boundary_band(target)) if boundary > 0 else None
        w_sum = None if wmask is None else (pix * wmask).sum()
        if not self.enabled:
            bce = local_sum / local_n.clamp_min(1.0)
            main = bce if w_sum is None else w_sum / wmask.sum().clamp_min(1.0)
            loss = main if jac is None else main + jaccard * jac / max(logits.shape[0], 1)
            return loss, float(bce.detach())
        s = self.all_sum([float(local_sum.detach()), float(local_n), float(logits.shape[0]),
                          0.0 if wmask is None else float(wmask.sum())])
        n = max(s[1], 1.0)
        loss = local_sum * (self.world / n) if w_sum is None else w_sum * (self.world / max(s[3], 1.0))
        if jac is not None:
            loss = loss + jaccard * jac * (self.world / max(s[2], 1.0))
        return loss, s[0] / n

    def all_sum(self, values: list[float]) -> list[float]:
        """Element-wise sum over ranks (float64; identity with one process)."""
        if not self.enabled:
            return list(values)
        import torch.distributed as dist

        t = torch.tensor(values, dtype=torch.float64, device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.SUM)
        return t.tolist()

    def agree(self, flag: bool) -> bool:
        """Rank 0's decision on every rank (wall-clock budgets differ by a few ms between ranks)."""
        if not self.enabled:
            return flag
        import torch.distributed as dist

        t = torch.tensor([1 if flag else 0], device=self.device)
        dist.broadcast(t, src=0)
        return bool(t.item())

    def all_agree(self, flag: bool) -> bool:
        """True on every rank only when ``flag`` is true on every rank (one process: ``flag``).

        Why not `agree`: a decision about this machine's memory is each rank's own to veto; rank
        0's view of its machine says nothing of another node's.
        """
        if not self.enabled:
            return flag
        return self.all_sum([0.0 if flag else 1.0])[0] == 0.0

    def shard(self, n: int) -> np.ndarray:
        """Indices of ``n`` items this rank evaluates."""
        return np.arange(self.rank, n, self.world)

    def close(self) -> None:
        if self.enabled and self.owns_group:
            import torch.distributed as dist

            dist.barrier()
            dist.destroy_process_group()
