"""Cutting a reference motion into fixed-length segments and describing each one."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rd_pipeline.files import open_npz

SEGMENTS_FILE = "segments.npz"
"""File name of the segment statistics inside a `stats` artifact."""


@dataclass(frozen=True)
class SegmentStats:
    """Per-segment occupancy of the selected joints, and per-joint spread of the whole reference."""

    fps: float
    """Frame rate of the reference."""
    starts: np.ndarray
    """(S,) first frame of each segment."""
    lengths: np.ndarray
    """(S,) frames in each segment; the last one may differ from the rest (a short remainder is
    merged into it)."""
    joint_names: tuple[str, ...]
    """All reference joints (policy order of the robot config)."""
    joint_std: np.ndarray
    """(J,) standard deviation of each joint over the whole reference, rad."""
    selected: tuple[str, ...]
    """Joints of the occupancy subspace (hip and knee pitch)."""
    bin_edges: np.ndarray
    """(K, B+1) histogram bin edges per selected joint, spanning its limits."""
    histograms: np.ndarray
    """(S, K, B) occupancy of each segment, each joint's histogram normalized to sum 1."""

    @property
    def n_segments(self) -> int:
        return len(self.starts)

    def save(self, path: Path) -> None:
        np.savez(
            path,
            fps=self.fps,
            starts=self.starts,
            lengths=self.lengths,
            joint_names=np.array(self.joint_names),
            joint_std=self.joint_std,
            selected=np.array(self.selected),
            bin_edges=self.bin_edges,
            histograms=self.histograms,
        )

    @classmethod
    def load(cls, path: Path) -> SegmentStats:
        with open_npz(path) as data:
            return cls(
                fps=float(data["fps"]),
                starts=data["starts"],
                lengths=data["lengths"],
                joint_names=tuple(str(n) for n in data["joint_names"]),
                joint_std=data["joint_std"],
                selected=tuple(str(n) for n in data["selected"]),
                bin_edges=data["bin_edges"],
                histograms=data["histograms"],
            )


def segment_bounds(n_frames: int, fps: float, segment_s: float, min_last_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of consecutive segments; a last piece shorter than `min_last_s` joins its neighbour."""
    size = max(1, int(round(segment_s * fps)))
    starts = np.arange(0, n_frames, size)
    lengths = np.minimum(size, n_frames - starts)
    if len(starts) > 1 and lengths[-1] < min_last_s * fps:
        lengths[-2] += lengths[-1]
        starts = starts[:-1]
        lengths = lengths[:-1]
    return starts, lengths


def segment_statistics(
    joint_pos: np.ndarray,
    joint_names: tuple[str, ...],
    fps: float,
    selected: tuple[str, ...],
    limits: np.ndarray,
    segment_s: float,
    min_last_s: float,
    bins: int,
) -> SegmentStats:
    """Histograms of `selected` joints per segment, with bins spanning each joint's limits (K, 2)."""
    starts, lengths = segment_bounds(joint_pos.shape[0], fps, segment_s, min_last_s)
    columns = [joint_names.index(j) for j in selected]
    edges = np.stack([np.linspace(lo, hi, bins + 1) for lo, hi in limits])
    histograms = np.zeros((len(starts), len(selected), bins))
    for s, (start, length) in enumerate(zip(starts, lengths)):
        window = joint_pos[start : start + length]
        for k, column in enumerate(columns):
            counts, _ = np.histogram(np.clip(window[:, column], edges[k, 0], edges[k, -1]), bins=edges[k])
            histograms[s, k] = counts / counts.sum()
    return SegmentStats(
        fps=fps,
        starts=starts,
        lengths=lengths,
        joint_names=joint_names,
        joint_std=joint_pos.std(axis=0),
        selected=selected,
        bin_edges=edges,
        histograms=histograms,
    )


def std_ranking(stats: SegmentStats, candidates: tuple[str, ...], mask: tuple[str, ...]) -> dict:
    """Joints ranked by reference std (the paper's candidate signal) and how the configured mask compares."""
    order = sorted(candidates, key=lambda j: -stats.joint_std[stats.joint_names.index(j)])
    top = order[: len(mask)]
    return {
        "ranked": [
            {"joint": j, "std_rad": round(float(stats.joint_std[stats.joint_names.index(j)]), 4)} for j in order
        ],
        "mask": list(mask),
        "mask_ranks": {j: order.index(j) + 1 for j in mask},
        "top_k_by_std": top,
        "mask_in_top_k": len(set(top) & set(mask)),
        "agrees": set(top) == set(mask),
    }
