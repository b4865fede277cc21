"""`rd-pipeline view` writes a headless rerun recording that reads back with the right content."""

from __future__ import annotations

from pathlib import Path

from rerun.chunk import RrdReader

from conftest import cli


def _rows_per_entity(path: Path) -> dict[str, int]:
    rows: dict[str, int] = {}
    for chunk in RrdReader(str(path)).store().stream():
        if not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def test_view_human_skeleton(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "dance.rrd"
    result = cli("view", "--robot", "g1", "--motion", "dance1_subject2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    rows = _rows_per_entity(out)
    assert rows == {"/human/joints": 3945, "/human/bones": 3945}


def test_view_imported_robot_reference(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "h1.rrd"
    result = cli("view", "--robot", "h1", "--motion", "dance2_subject3", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert _rows_per_entity(out) == {"/robot/import/joints": 11285, "/robot/import/bones": 11285}
