"""Variants of a LAFAN1 take that a retargeter tuned on the take has not seen: mirrored, played
faster or slower, and the floor work cut out of it so the clip starts lying or crawling.

A rule that holds only on the takes it was tuned on breaks on these: a mirrored take swaps which
foot leads, a change of tempo changes every speed threshold's meaning, and a cut starts the
clip without the standing prelude a ground estimate may lean on.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.contact import contact_runs
from rd_pipeline.motion.human import HumanMotion

MIRROR = np.diag([1.0, -1.0, 1.0])
"""The reflection across the world's x-z plane (LAFAN1 in Z-up: y is the performer's side)."""


def mirrored(human: HumanMotion) -> HumanMotion:
    """The take reflected left to right: positions reflected, every Left joint swapped with its
    Right twin, orientations conjugated by the reflection (a proper rotation again)."""
    twin = [_twin_index(human.names, name) for name in human.names]
    pos = np.einsum("ab,tjb->tja", MIRROR, human.pos_w)[:, twin]
    rot = _matrices(human.quat_w)
    rot = np.einsum("ab,tjbc,cd->tjad", MIRROR, rot, MIRROR)[:, twin]
    offsets = human.offsets[twin] * np.diag(MIRROR)
    return dataclasses.replace(human, pos_w=pos, quat_w=_quaternions(rot), offsets=offsets)


def played_at(human: HumanMotion, tempo: float) -> HumanMotion:
    """The take played `tempo` times faster (the same frames at a scaled frame rate)."""
    return dataclasses.replace(human, fps=human.fps * tempo)


def floor_cuts(
    human: HumanMotion,
    pelvis: str,
    low_m: float,
    min_s: float,
    length_s: float,
    count: int,
    into: float = 0.25,
) -> list[tuple[float, HumanMotion]]:
    """Up to `count` clips of `length_s` cut out of the take, each starting inside a stretch where
    the `pelvis` joint stays below `low_m` for at least `min_s` (lying, sitting, crawling): the
    longest stretches first, each cut `into` of the way through its stretch (a quarter: well past
    the way down, so the clip opens on the floor). Returns (start second in the take, clip) pairs."""
    z = human.pos_w[:, human.names.index(pelvis), 2]
    shortest = int(round(min_s * human.fps))
    runs = [run for run in contact_runs(z < low_m) if run[1] - run[0] >= shortest]
    runs.sort(key=lambda run: run[0] - run[1])
    frames = int(round(length_s * human.fps))
    cuts = []
    for start, end in runs[:count]:
        first = min(start + int((end - start) * into), max(human.n_frames - frames, 0))
        cuts.append((first / human.fps, _frames(human, first, first + frames)))
    return sorted(cuts, key=lambda cut: cut[0])


def _frames(human: HumanMotion, start: int, end: int) -> HumanMotion:
    return dataclasses.replace(human, pos_w=human.pos_w[start:end], quat_w=human.quat_w[start:end])


def _twin_index(names: tuple[str, ...], name: str) -> int:
    for side, other in (("Left", "Right"), ("Right", "Left")):
        if name.startswith(side):
            return names.index(other + name[len(side) :])
    return names.index(name)


def _matrices(quat_wxyz: np.ndarray) -> np.ndarray:
    flat = quat_wxyz.reshape(-1, 4)[:, [1, 2, 3, 0]]
    return Rotation.from_quat(flat).as_matrix().reshape(*quat_wxyz.shape[:-1], 3, 3)


def _quaternions(matrices: np.ndarray) -> np.ndarray:
    flat = Rotation.from_matrix(matrices.reshape(-1, 3, 3)).as_quat()[:, [3, 0, 1, 2]]
    return flat.reshape(*matrices.shape[:-2], 4)
