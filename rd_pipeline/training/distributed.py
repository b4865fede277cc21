"""Data-parallel PPO across processes: where a process sits among the ranks, and the few collectives
the training loop needs besides rsl-rl's own.

rsl-rl's PPO already averages gradients, the KL of its adaptive learning rate and the observation
normalizer's statistics over `torch.distributed` once a process group exists; its runner only ever
creates one with NCCL on CUDA. Here the group is `gloo` on CPU and `nccl` on CUDA, so the same
scheme runs on a laptop's cores, a workstation's GPUs and several machines (torchrun's rendezvous).
Every rank steps its own environments; rank 0 alone writes the checkpoints and the log.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.distributed as dist


@dataclass(frozen=True)
class Ranks:
    """Where this process sits among the training processes."""

    rank: int = 0
    """Global rank (0 writes the artifact)."""
    world_size: int = 1
    """Training processes in all."""
    local_world_size: int = 1
    """Training processes on this machine (they share its cores)."""

    @property
    def leader(self) -> bool:
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.world_size > 1

    def seed(self, seed: int) -> int:
        """This rank's seed for its environments and sampler: `seed` itself on rank 0 (a
        single-process run is unchanged), an independent stream of the same seed elsewhere."""
        if self.rank == 0:
            return seed
        return int(np.random.SeedSequence([seed, self.rank]).generate_state(1)[0])


ONE_PROCESS = Ranks()
"""The ranks of an ordinary training: one process."""


def join_process_group(device: str) -> Ranks:
    """Join the group torchrun describes in the environment (`RANK`, `WORLD_SIZE`,
    `LOCAL_WORLD_SIZE`, `MASTER_ADDR`, `MASTER_PORT`): gloo for CPU tensors, NCCL for CUDA."""
    ranks = Ranks(
        rank=int(os.environ["RANK"]),
        world_size=int(os.environ["WORLD_SIZE"]),
        local_world_size=int(os.environ.get("LOCAL_WORLD_SIZE", os.environ["WORLD_SIZE"])),
    )
    backend = "nccl" if device.startswith("cuda") else "gloo"
    if backend == "nccl":
        torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group(backend=backend, rank=ranks.rank, world_size=ranks.world_size)
    return ranks


def leave_process_group() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def gather_to_leader(ranks: Ranks, value: Any) -> list[Any]:
    """Every rank's `value`, in rank order, on rank 0 (an empty list elsewhere)."""
    if not ranks.distributed:
        return [value]
    gathered: list[Any] = [None] * ranks.world_size if ranks.leader else []
    dist.gather_object(value, gathered if ranks.leader else None, dst=0)
    return gathered


def summed(ranks: Ranks, values: list[float]) -> list[float]:
    """`values` summed over the ranks (float64, so counts stay exact)."""
    if not ranks.distributed:
        return values
    # NCCL reduces only tensors on this rank's GPU.
    device = torch.device("cuda", torch.cuda.current_device()) if dist.get_backend() == "nccl" else None
    tensor = torch.tensor(values, dtype=torch.float64, device=device)
    dist.all_reduce(tensor)
    return tensor.tolist()


def weights_digest(module: torch.nn.Module) -> str:
    """A short hash of a module's parameters and buffers, bit for bit: equal digests on every
    rank after an update are what data-parallel training promises."""
    digest = hashlib.sha256()
    for name, tensor in module.state_dict().items():
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()[:16]
