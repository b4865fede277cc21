"""BVH parsing on real LAFAN1 files, a synthetic file with unusual channels, and every kind of bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import LAFAN_DIR, cli
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.bvh import forward_kinematics, read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.motion.lafan import LAFAN_JOINTS


@pytest.fixture(scope="module")
def dance() -> Path:
    return LAFAN_DIR / "dance1_subject2.bvh"


def test_lafan_dance_hierarchy_and_frames(dance: Path) -> None:
    clip = read_bvh(dance)
    joints = [n for n in clip.names if not n.endswith("_end")]
    assert tuple(joints) == LAFAN_JOINTS
    assert len(clip.names) - len(joints) == 5  # End Sites of toes, head and hands
    assert clip.channels.shape == (3945, 69)
    assert clip.frame_time == pytest.approx(0.033333)
    # First motion line of the file: root position and the first rotation channel.
    assert clip.channels[0, :4] == pytest.approx([193.614899, 90.217430, 358.243408, 90.722131])


def test_lafan_motion_is_z_up_metres_with_rigid_bones(dance: Path) -> None:
    human = human_motion_from_bvh(read_bvh(dance), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    names = list(human.names)
    head, hips = names.index("Head"), names.index("Hips")
    feet = [names.index("LeftToe"), names.index("RightToe")]
    assert human.pos_w.shape == (3945, 27, 3)
    # Standing dancer: head about 0.6-0.8 m above the hips, lowest toe within 3 cm of the floor.
    assert 0.4 < float(np.median(human.pos_w[:, head, 2] - human.pos_w[:, hips, 2])) < 0.9
    assert abs(float(np.median(human.pos_w[:, feet, 2].min(axis=1)))) < 0.03
    # Root position is the channel value (cm, Y-up) mapped to Z-up metres: (x, -z, y) / 100.
    x, y, z = 193.614899, 90.217430, 358.243408
    assert human.pos_w[0, hips] == pytest.approx([x / 100, -z / 100, y / 100])
    # Bone lengths stay equal to the skeleton offsets in every frame.
    for j, parent in enumerate(human.parents):
        if parent >= 0:
            length = np.linalg.norm(human.pos_w[:, j] - human.pos_w[:, parent], axis=1)
            assert np.abs(length - np.linalg.norm(human.offsets[j])).max() < 1e-9
    assert np.allclose(np.linalg.norm(human.quat_w, axis=-1), 1.0)


SYNTHETIC = """HIERARCHY
ROOT root
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation
  JOINT slider
  {
    OFFSET 0 10 0
    CHANNELS 4 Yrotation Xposition Zrotation Yposition
    End Site
    {
      OFFSET 0 0 5
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.02
0 0 0 0 0 0 0 0 0 0
1 2 3 30 -20 10 45 7 -60 8
"""


def test_any_channel_order_and_position_channels(tmp_path: Path) -> None:
    path = tmp_path / "synthetic.bvh"
    path.write_text(SYNTHETIC)
    clip = read_bvh(path)
    assert clip.names == ["root", "slider", "slider_end"]
    pos, rot = forward_kinematics(clip)
    root_rot = Rotation.from_euler("XYZ", [30, -20, 10], degrees=True).as_matrix()
    slider_local = Rotation.from_euler("YZ", [45, -60], degrees=True).as_matrix()
    assert np.allclose(pos[1, 0], [1, 2, 3]) and np.allclose(rot[1, 0], root_rot)
    # Position channels replace the OFFSET: local translation (7, 8, 0), X then Y as listed.
    assert np.allclose(pos[1, 1], [1, 2, 3] + root_rot @ [7, 8, 0])
    assert np.allclose(rot[1, 1], root_rot @ slider_local)
    assert np.allclose(pos[1, 2], pos[1, 1] + rot[1, 1] @ [0, 0, 5])
    # Frame 0 is the rest pose with zero channel values.
    assert np.allclose(pos[0], [[0, 0, 0], [0, 0, 0], [0, 0, 5]])


def _lines(dance: Path) -> list[str]:
    return dance.read_text().splitlines()


def _corrupt(dance: Path, tmp_path: Path, change) -> Path:
    lines = _lines(dance)
    change(lines)
    path = tmp_path / "dance1_subject2.bvh"
    path.write_text("\n".join(lines) + "\n")
    return path


def _set_value(line_index: int, value: str):
    def change(lines: list[str]) -> None:
        parts = lines[line_index].split()
        parts[5] = value
        lines[line_index] = " ".join(parts)

    return change


BAD_INPUTS = {
    # name: (edit of the file's lines, expected 1-based line number, message)
    "truncated": (
        lambda lines: lines.__delitem__(slice(3000, None)),
        3000,
        "truncated: Frames says 3945 but the file has 2866 motion lines",
    ),
    "short line": (
        lambda lines: lines.__setitem__(499, " ".join(lines[499].split()[:-1])),
        500,
        "expected 69 values on a motion line, got 68",
    ),
    "non-numeric": (_set_value(699, "abc"), 700, "non-numeric value 'abc'"),
    "nan": (_set_value(799, "nan"), 800, "non-finite value 'nan'"),
    "inf": (_set_value(899, "-inf"), 900, "non-finite value '-inf'"),
    "zero frame time": (
        lambda lines: lines.__setitem__(133, "Frame Time: 0"),
        134,
        "Frame Time must be a positive number, got 0.0",
    ),
    "negative frame time": (
        lambda lines: lines.__setitem__(133, "Frame Time: -0.033333"),
        134,
        "Frame Time must be a positive number, got -0.033333",
    ),
    "a 10 s frame time": (
        lambda lines: lines.__setitem__(133, "Frame Time: 10"),
        134,
        "Frame Time 10 s is 0.1 fps; motion capture is 20 to 500 fps (Frame Time 0.002 to 0.05 s)",
    ),
    "a 10 kHz frame time": (
        lambda lines: lines.__setitem__(133, "Frame Time: 0.0001"),
        134,
        "Frame Time 0.0001 s is 1e+04 fps; motion capture is 20 to 500 fps (Frame Time 0.002 to 0.05 s)",
    ),
    "no motion section": (
        lambda lines: lines.__delitem__(slice(131, None)),
        131,
        "file ends before the MOTION section",
    ),
}


def test_header_one_frame_over_whole_lines_is_read_with_a_warning(tmp_path: Path) -> None:
    """fallAndGetUp1_subject1 as distributed: `Frames: 5047` over 5046 whole motion lines."""
    path = LAFAN_DIR / "fallAndGetUp1_subject1.bvh"
    clip = read_bvh(path)
    assert clip.channels.shape == (5046, 69)
    assert clip.warnings == (f"{path}: Frames says 5047 but the file has 5046 whole motion lines; read 5046",)
    result = cli(
        "run",
        "--robot",
        "g1",
        "--motion",
        "fallAndGetUp1_subject1",
        "--until",
        "parse",
        env={"RD_ARTIFACTS": str(tmp_path / "store")},
    )
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    (warning,) = warnings  # the CLI names the file by its resolved path
    assert warning.startswith("warning: /")
    message = "Frames says 5047 but the file has 5046 whole motion lines; read 5046"
    assert warning.endswith(f"/fallAndGetUp1_subject1.bvh: {message}")


def test_header_one_frame_over_a_cut_line_stays_an_error(dance: Path, tmp_path: Path) -> None:
    lines = _lines(dance)
    lines[132] = "Frames: 3946"
    lines[-1] = " ".join(lines[-1].split()[:40])
    path = tmp_path / "dance1_subject2.bvh"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(PipelineError) as error:
        read_bvh(path)
    assert str(error.value) == f"{path}:{len(lines)}: expected 69 values on a motion line, got 40"


def test_dance_reads_without_warnings(dance: Path) -> None:
    assert read_bvh(dance).warnings == ()


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_names_file_and_line(case: str, dance: Path, tmp_path: Path) -> None:
    change, line, message = BAD_INPUTS[case]
    path = _corrupt(dance, tmp_path, change)
    with pytest.raises(PipelineError) as error:
        read_bvh(path)
    assert str(error.value) == f"{path}:{line}: {message}"


def test_bad_input_through_the_cli_is_one_line_and_leaves_no_artifact(dance: Path, tmp_path: Path) -> None:
    path = _corrupt(dance, tmp_path, _set_value(699, "nan"))
    store = tmp_path / "store"
    result = cli(
        "run",
        "--robot",
        "g1",
        "--motion",
        "dance1_subject2",
        "--until",
        "parse",
        env={"RD_LAFAN_DIR": str(tmp_path), "RD_ARTIFACTS": str(store)},
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    error_lines = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert error_lines == [f"error: {path}:700: non-finite value 'nan'"]
    leftovers = [p for p in (store / "parse" / "dance1_subject2").iterdir()] if (store / "parse").exists() else []
    assert leftovers == []
