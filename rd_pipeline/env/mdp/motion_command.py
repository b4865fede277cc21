"""The motion command: the reference the policy tracks, as mjlab's tracking task has it.

It owns the reference tensors on the training device, each environment's current and start frame,
and the segment sampler with its bookkeeping: where episodes start (a frame inside a segment the
sampler picks) and, when they end, which segments they started, reached and failed in.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from rd_pipeline.env.mdp.events import ReferenceFrames
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.sampling.sampler import SegmentSampler

Tensorize = Callable[..., torch.Tensor]
"""Makes a tensor of the training device and dtype from an array."""


class MotionCommand:
    """The reference motion and the per-environment frames that step along it."""

    def __init__(
        self,
        reference: ReferenceMotion,
        tracked_bodies: list[str],
        root_body: str,
        sampler: SegmentSampler,
        segment_starts: np.ndarray,
        segment_lengths: np.ndarray,
        num_envs: int,
        tensor: Tensorize,
    ) -> None:
        self.sampler = sampler
        self.segment_starts = torch.as_tensor(segment_starts)
        self.segment_lengths = torch.as_tensor(segment_lengths)
        self.n_frames = reference.n_frames
        bodies = [reference.body_names.index(b) for b in tracked_bodies]
        root = reference.body_names.index(root_body)
        self.ref = ReferenceFrames(
            root_pos=tensor(reference.root_pos),
            root_quat=tensor(reference.root_quat),
            root_lin_vel=tensor(reference.body_lin_vel_w[:, root]),
            root_ang_vel=tensor(reference.body_ang_vel_w[:, root]),
            joint_pos=tensor(reference.joint_pos),
            joint_vel=tensor(reference.joint_vel),
        )
        self.body_pos = tensor(reference.body_pos_w[:, bodies])
        self.body_quat = tensor(reference.body_quat_w[:, bodies])
        self.body_lin_vel = tensor(reference.body_lin_vel_w[:, bodies])
        self.body_ang_vel = tensor(reference.body_ang_vel_w[:, bodies])
        self.contact = tensor(reference.foot_contact, torch.bool)
        self.frame = torch.zeros(num_envs, dtype=torch.long, device=self.body_pos.device)
        # Episode starts live on the host beside the random generator and the sampler.
        self.start_frame = torch.zeros(num_envs, dtype=torch.long)

    def sample_start_frames(self, count: int, rng: np.random.Generator) -> torch.Tensor:
        """(count,) host start frames: a segment from the sampler, then a uniform frame inside it."""
        segments = self.sampler.sample(count)
        offsets = torch.as_tensor(rng.random(count)) * self.segment_lengths[segments]
        frames = self.segment_starts[segments] + offsets.long()
        return frames.clamp(max=self.n_frames - 2)

    def start(self, host_ids: torch.Tensor, frames: torch.Tensor) -> None:
        """Episodes of `host_ids` start at host `frames`."""
        self.start_frame[host_ids] = frames
        self.frame[host_ids.to(self.frame.device)] = frames.to(self.frame.device)

    def next_frame(self) -> torch.Tensor:
        """(N,) the frame each environment reaches at the next control step."""
        return (self.frame + 1).clamp(max=self.n_frames - 1)

    def frames_ahead(self, steps: tuple[int, ...]) -> torch.Tensor:
        """(N, K) the frame each environment reaches each of `steps` control steps ahead."""
        ahead = torch.as_tensor(steps, dtype=self.frame.dtype, device=self.frame.device)
        return (self.frame[:, None] + ahead).clamp(max=self.n_frames - 1)

    def advance(self) -> None:
        self.frame = self.next_frame()

    def time_out(self) -> torch.Tensor:
        """(N,) True where the reference has reached its last frame."""
        return self.frame >= self.n_frames - 1

    def record_ends(self, done_ids: torch.Tensor, lengths: torch.Tensor, failed: torch.Tensor) -> None:
        """Tell the sampler where the episodes of host `done_ids` started, ended and whether they
        failed, then count one sampler step."""
        end_frames = (self.start_frame[done_ids] + lengths).clamp(max=self.n_frames - 1)
        start_segments = self.segment_of(self.start_frame[done_ids])
        self.sampler.record(start_segments, self.segment_of(end_frames), failed)
        self.sampler.advance(1)

    def segment_of(self, frames: torch.Tensor) -> torch.Tensor:
        """The sampler segment each reference frame lies in."""
        return (torch.searchsorted(self.segment_starts, frames, right=True) - 1).clamp(min=0)
