"""A general BVH reader and vectorized forward kinematics.

Any rotation channel order, position channels on any joint (they give the joint's local
translation, replacing its OFFSET, as LAFAN1 and most exporters write the root), and End Sites
(kept as channel-less joints named `<parent>_end`). Errors name the file and line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import PLAUSIBLE_FPS

_ROTATION_CHANNELS = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POSITION_CHANNELS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


@dataclass(frozen=True)
class BvhJoint:
    """One node of the BVH hierarchy."""

    name: str
    """Joint name (End Sites: `<parent>_end`)."""
    parent: int
    """Index of the parent joint, -1 for the root."""
    offset: np.ndarray
    """Rest translation from the parent, file units."""
    channels: tuple[str, ...]
    """Channel names in file order (empty for End Sites)."""
    first_channel: int
    """Column of the first channel in a motion line."""


@dataclass(frozen=True)
class BvhClip:
    """A parsed BVH file: the hierarchy and the raw channel values."""

    joints: tuple[BvhJoint, ...]
    """Joints in file order; a parent always precedes its children."""
    frame_time: float
    """Seconds per frame."""
    channels: np.ndarray
    """(T, C) channel values in file order (degrees, file units)."""
    warnings: tuple[str, ...] = ()
    """Quirks of the file that were read past (e.g. a `Frames:` count one more than the lines)."""

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def parents(self) -> np.ndarray:
        return np.array([j.parent for j in self.joints], dtype=np.int64)


def read_bvh(path: Path) -> BvhClip:
    """Parse a BVH file. Any defect raises `PipelineError("<file>:<line>: <what>")`."""
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        raise PipelineError(f"{path}: cannot read BVH ({exc})") from None
    return _Parser(path, text.splitlines()).parse()


class _Parser:
    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.lines = lines
        self.pos = 0
        self.joints: list[BvhJoint] = []
        self.n_channels = 0
        self.warnings: list[str] = []

    def fail(self, message: str, line: int | None = None) -> PipelineError:
        line = self.pos if line is None else line
        return PipelineError(f"{self.path}:{line}: {message}")

    def next_tokens(self) -> list[str]:
        """Tokens of the next non-empty line (braces split off); fails at end of file."""
        while self.pos < len(self.lines):
            self.pos += 1
            tokens = self.lines[self.pos - 1].replace("{", " { ").replace("}", " } ").split()
            if tokens:
                return tokens
        raise self.fail("file ends before the MOTION section")

    def parse(self) -> BvhClip:
        tokens = self.next_tokens()
        if tokens != ["HIERARCHY"]:
            raise self.fail(f"expected HIERARCHY, got '{' '.join(tokens)}'")
        tokens = self.next_tokens()
        if len(tokens) != 2 or tokens[0] != "ROOT":
            raise self.fail(f"expected 'ROOT <name>', got '{' '.join(tokens)}'")
        self.parse_joint(tokens[1], parent=-1)
        tokens = self.next_tokens()
        if tokens != ["MOTION"]:
            raise self.fail(f"expected MOTION after the hierarchy, got '{' '.join(tokens)}'")
        n_frames = self.header_number("Frames:", int)
        if n_frames < 1:
            raise self.fail(f"Frames must be at least 1, got {n_frames}")
        frame_time = self.header_number("Frame Time:", float)
        if not np.isfinite(frame_time) or frame_time <= 0:
            raise self.fail(f"Frame Time must be a positive number, got {frame_time}")
        low, high = PLAUSIBLE_FPS
        if not low <= 1.0 / frame_time <= high:
            raise self.fail(
                f"Frame Time {frame_time:g} s is {1.0 / frame_time:.4g} fps; motion capture is {low:g} to {high:g} fps "
                f"(Frame Time {1.0 / high:g} to {1.0 / low:g} s)"
            )
        channels = self.motion_block(n_frames)
        return BvhClip(tuple(self.joints), frame_time, channels, tuple(self.warnings))

    def parse_joint(self, name: str, parent: int) -> None:
        if self.next_tokens() != ["{"]:
            raise self.fail(f"expected '{{' after joint '{name}'")
        offset = self.offset()
        tokens = self.next_tokens()
        if tokens[0] != "CHANNELS":
            raise self.fail(f"expected CHANNELS for joint '{name}', got '{tokens[0]}'")
        try:
            count = int(tokens[1])
        except (IndexError, ValueError):
            raise self.fail("CHANNELS needs a count") from None
        channels = tuple(tokens[2:])
        if len(channels) != count:
            raise self.fail(f"CHANNELS says {count} but lists {len(channels)}")
        for channel in channels:
            if channel not in _ROTATION_CHANNELS and channel not in _POSITION_CHANNELS:
                raise self.fail(f"unknown channel '{channel}'")
        index = len(self.joints)
        self.joints.append(BvhJoint(name, parent, offset, channels, self.n_channels))
        self.n_channels += count
        while True:
            tokens = self.next_tokens()
            if tokens == ["}"]:
                return
            if tokens[0] == "JOINT" and len(tokens) == 2:
                self.parse_joint(tokens[1], parent=index)
            elif tokens[:2] == ["End", "Site"]:
                if self.next_tokens() != ["{"]:
                    raise self.fail("expected '{' after End Site")
                end_offset = self.offset()
                if self.next_tokens() != ["}"]:
                    raise self.fail("expected '}' closing End Site")
                self.joints.append(BvhJoint(f"{name}_end", index, end_offset, (), self.n_channels))
            else:
                raise self.fail(f"expected JOINT, End Site or '}}', got '{' '.join(tokens)}'")

    def offset(self) -> np.ndarray:
        tokens = self.next_tokens()
        if tokens[0] != "OFFSET" or len(tokens) != 4:
            raise self.fail(f"expected 'OFFSET x y z', got '{' '.join(tokens)}'")
        values = self.numbers(tokens[1:], self.pos)
        return values

    def header_number(self, label: str, kind: type):
        line = self.lines[self.pos] if self.pos < len(self.lines) else ""
        self.pos += 1
        if not line.strip().startswith(label):
            raise self.fail(f"expected '{label}', got '{line.strip()}'")
        try:
            return kind(line.strip()[len(label) :].strip())
        except ValueError:
            raise self.fail(f"'{label}' needs a number, got '{line.strip()[len(label) :].strip()}'") from None

    def numbers(self, tokens: list[str], line: int) -> np.ndarray:
        try:
            values = np.array(tokens, dtype=np.float64)
        except ValueError:
            bad = next(t for t in tokens if not is_float(t))
            raise self.fail(f"non-numeric value '{bad}'", line) from None
        if not np.all(np.isfinite(values)):
            bad = tokens[int(np.flatnonzero(~np.isfinite(values))[0])]
            raise self.fail(f"non-finite value '{bad}'", line)
        return values

    def motion_block(self, n_frames: int) -> np.ndarray:
        first = self.pos  # 0-based index of the first motion line
        rows = [line.split() for line in self.lines[first:]]
        while rows and not rows[-1]:
            rows.pop()
        for i, row in enumerate(rows):
            if len(row) != self.n_channels:
                raise self.fail(f"expected {self.n_channels} values on a motion line, got {len(row)}", first + i + 1)
        if rows and len(rows) == n_frames - 1:
            # Some distributed LAFAN1 takes count one frame more than they hold; every line is whole,
            # so the data is complete and only the header is off.
            self.warnings.append(
                f"{self.path}: Frames says {n_frames} but the file has {len(rows)} whole motion lines; read {len(rows)}"
            )
            n_frames = len(rows)
        if len(rows) < n_frames:
            raise self.fail(
                f"truncated: Frames says {n_frames} but the file has {len(rows)} motion lines", first + len(rows)
            )
        if len(rows) > n_frames:
            raise self.fail(f"{len(rows) - n_frames} motion lines beyond Frames: {n_frames}", first + n_frames + 1)
        flat = [token for row in rows for token in row]
        try:
            values = np.array(flat, dtype=np.float64).reshape(n_frames, self.n_channels)
        except ValueError:
            i = next(i for i, row in enumerate(rows) if not all(is_float(t) for t in row))
            self.numbers(rows[i], first + i + 1)
            raise  # unreachable: numbers() raised
        bad = ~np.isfinite(values)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise self.fail(f"non-finite value '{rows[i][j]}'", first + int(i) + 1)
        return values


def is_float(token: str) -> bool:
    """Whether `float(token)` succeeds (used to point at the offending value in error messages)."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def _axis_rotation(axis: str, angle: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by `angle` (rad) about one coordinate axis."""
    c = np.cos(angle)
    s = np.sin(angle)
    i, k = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    out = np.zeros((angle.shape[0], 3, 3))
    out[:, 3 - i - k, 3 - i - k] = 1.0
    out[:, i, i] = c
    out[:, i, k] = -s
    out[:, k, i] = s
    out[:, k, k] = c
    return out


def forward_kinematics(clip: BvhClip) -> tuple[np.ndarray, np.ndarray]:
    """Global joint positions (T, J, 3) in file units and rotation matrices (T, J, 3, 3)."""
    n_frames = clip.channels.shape[0]
    n_joints = len(clip.joints)
    local_rot = np.broadcast_to(np.eye(3), (n_frames, n_joints, 3, 3)).copy()
    local_pos = np.empty((n_frames, n_joints, 3))
    for j, joint in enumerate(clip.joints):
        local_pos[:, j] = joint.offset
        rot_columns = []
        axes = ""
        for k, channel in enumerate(joint.channels):
            column = clip.channels[:, joint.first_channel + k]
            if channel in _POSITION_CHANNELS:
                local_pos[:, j, _POSITION_CHANNELS[channel]] = column
            else:
                rot_columns.append(column)
                axes += _ROTATION_CHANNELS[channel]
        for axis, column in zip(axes, rot_columns):
            # Intrinsic rotations composed in channel order (the BVH convention).
            local_rot[:, j] = local_rot[:, j] @ _axis_rotation(axis, np.deg2rad(column))
    global_rot = np.empty_like(local_rot)
    global_pos = np.empty_like(local_pos)
    for j, joint in enumerate(clip.joints):
        if joint.parent < 0:
            global_rot[:, j] = local_rot[:, j]
            global_pos[:, j] = local_pos[:, j]
        else:
            parent_rot = global_rot[:, joint.parent]
            global_rot[:, j] = parent_rot @ local_rot[:, j]
            global_pos[:, j] = global_pos[:, joint.parent] + np.einsum("tab,tb->ta", parent_rot, local_pos[:, j])
    return global_pos, global_rot
