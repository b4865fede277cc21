"""`rd-pipeline view` writes a headless rerun recording that reads back with the right content."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import cli
from rerun.chunk import RrdReader

from rd_pipeline.robots import load_robot


def _static(path: Path, entity: str) -> dict[str, list]:
    """`entity`'s static components (its look: colours, labels, meshes)."""
    found: dict[str, list] = {}
    for chunk in RrdReader(str(path)).store().stream():
        if chunk.is_static and chunk.entity_path == entity:
            batch = chunk.to_record_batch()
            found.update({name: batch.column(name).to_pylist() for name in batch.schema.names if ":" in name})
    return found


def _mesh_colors(path: Path, entity: str) -> list:
    """The colours of `entity`'s mesh (logged on the time axis at its first pose)."""
    colors = []
    for chunk in RrdReader(str(path)).store().stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == entity and "Mesh3D:albedo_factor" in batch.schema.names:
            colors += batch.column("Mesh3D:albedo_factor").to_pylist()
    return colors


def _view_names(path: Path) -> set[str]:
    """The titles of the views in the layout the recording opens with."""
    reader = RrdReader(str(path))
    (blueprint,) = reader.blueprints()
    names = set()
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:display_name" in batch.schema.names:
            names.update(n for row in batch.column("ViewBlueprint:display_name").to_pylist() for n in row)
    return names


def _rows_per_entity(path: Path) -> dict[str, int]:
    rows: dict[str, int] = {}
    for chunk in RrdReader(str(path)).store().stream():
        if not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


@pytest.mark.usefixtures("g1_dance_store")  # the session's retargeted take
@pytest.mark.slow
def test_view_human_and_retargeted_robot(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "dance.rrd"
    result = cli("view", "--robot", "g1", "--motion", "dance1_subject2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    rows = _rows_per_entity(out)
    assert rows.pop("/human/joints") == 3945 and rows.pop("/human/bones") == 3945
    # Each source named above its root, every frame, in its own colour.
    assert rows.pop("/human/label") == 3945 and rows.pop("/robot/retarget/label") == 6575
    labels = {entity: _static(out, entity) for entity in ("/human/label", "/robot/retarget/label")}
    assert labels["/human/label"]["Points3D:labels"] == [["human (motion capture)"]]
    assert labels["/robot/retarget/label"]["Points3D:labels"] == [["reference (retarget)"]]
    assert labels["/human/label"]["Points3D:colors"] != labels["/robot/retarget/label"]["Points3D:colors"]
    assert _static(out, "/human/bones")["LineStrips3D:colors"] != _mesh_colors(out, "/robot/retarget/pelvis")
    assert rows.pop("/targets/retarget") == 6575
    # The rulers as plots on the same timeline.
    plots = {name: rows.pop(name) for name in list(rows) if name.startswith("/quality/")}
    rulers = [
        "penetration_m",
        "keypoint_error_m",
        "pelvis_height_dev_m",
        "root_speed_m_s",
        "human_root_speed_m_s",
        "planted_foot_turn_deg",
    ]
    assert plots == {f"/quality/retarget/{name}": 6575 for name in rulers}
    # The scene above one plot per unit of the rulers.
    units = {"distances (m)", "speeds (m/s)", "angles (deg)"}
    assert _view_names(out) == {"scene"} | {f"retarget: {unit}" for unit in units}
    # One moving mesh per G1 body (all 24 have a visual mesh), every frame of the 50 Hz reference,
    # and the mesh itself, once, at the first frame.
    assert sorted(rows) == sorted(f"/robot/retarget/{b}" for b in load_robot("g1").body_names)
    assert set(rows.values()) == {6575 + 1}
    assert _mesh_colors(out, "/robot/retarget/left_ankle_roll_link")


@pytest.mark.slow
def test_view_imported_robot_reference(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "h1.rrd"
    result = cli("view", "--robot", "h1", "--motion", "dance2_subject3", "--out", str(out))
    assert result.returncode == 0, result.stderr
    planned = json.loads(cli("plan", "--robot", "h1", "--motion", "dance2_subject3", "--json").stdout)
    validate = next(row["key"] for row in planned if row["stage"] == "validate")
    said = " ".join(result.stderr.split())
    assert f"no validation {validate} of these params in the store: no tracked robot (profile smoke;" in said
    rows = _rows_per_entity(out)
    plots = {name: rows.pop(name) for name in list(rows) if name.startswith("/quality/")}
    assert plots == {f"/quality/import/{name}": 11285 for name in ("penetration_m", "root_speed_m_s")}
    assert rows.pop("/robot/import/label") == 11285
    assert sorted(rows) == sorted(f"/robot/import/{b}" for b in load_robot("h1").body_names)
    assert set(rows.values()) == {11285 + 1}


@pytest.mark.slow
def test_view_without_a_display_writes_the_recording_and_says_how_to_open_it(artifacts: Path) -> None:
    result = cli("view", "--robot", "h1", "--motion", "dance2_subject3", env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    assert result.returncode == 0, result.stderr
    out = artifacts / "views" / "h1_dance2_subject3.rrd"
    message = " ".join(result.stderr.split())
    assert f"wrote {out}; open it with `rerun {out}`" in message
    assert _rows_per_entity(out)["/robot/import/pelvis"] == 11285 + 1


@pytest.mark.slow
def test_view_out_to_a_folder_or_below_a_file_is_one_line_and_writes_nothing(artifacts: Path, tmp_path: Path) -> None:
    folder = tmp_path / "recordings"
    folder.mkdir()
    afile = tmp_path / "a-file"
    afile.write_text("")
    said = {}
    for out in (folder, afile / "take.rrd"):
        result = cli("view", "--robot", "h1", "--motion", "dance2_subject3", "--out", str(out))
        assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
        said[out] = result.stderr.strip().splitlines()[-1]
    assert said[folder] == f"error: cannot write the recording {folder} (Is a directory)"
    assert said[afile / "take.rrd"].startswith(f"error: cannot write the recording {afile}")
    assert list(folder.iterdir()) == [] and afile.read_text() == ""
