"""Benchmark: does mjlab's own `MotionLoader` read what `export-motion --format mjlab` writes?

    python -m bench.mjlab_interop --mjlab-python /path/to/mjlab-venv/bin/python [--motion dance1_subject2]

mjlab 1.6 pins rsl-rl-lib 5.4.2 and mujoco 3.11, this project rsl-rl-lib 5.5 and mujoco 4, so mjlab
cannot share the project's environment (nor be one of its extras). Give it a venv of its own:

    python -m venv mjlab-venv && mjlab-venv/bin/pip install torch==2.13.0 mjlab==1.6.0

This script exports G1 motions from both sources (retarget and import) with the project, then runs
itself in that venv (`--check`, which imports only mjlab, torch and numpy) to build mjlab's G1
entity and its flat tracking task's motion command config, load each file with `MotionLoader` at the
task's body indexes, and check the layout and the kinematics against mjlab's own G1 model. Writes
`bench/results/mjlab_interop.json`.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

RESULTS = Path(__file__).parent / "results" / "mjlab_interop.json"
SAMPLED_FRAMES = 50


def check(files: list[str]) -> dict:
    """In mjlab's venv: load every file as mjlab's G1 tracking task would, and measure it."""
    import mujoco
    import numpy as np
    import torch
    from mjlab.asset_zoo.robots.unitree_g1.g1_constants import get_g1_robot_cfg, get_spec
    from mjlab.entity import Entity
    from mjlab.tasks.tracking.config.g1.env_cfgs import unitree_g1_flat_tracking_env_cfg
    from mjlab.tasks.tracking.mdp.commands import MotionLoader

    entity = Entity(get_g1_robot_cfg())
    tracked = unitree_g1_flat_tracking_env_cfg().commands["motion"].body_names
    body_indexes, _ = entity.find_bodies(tracked, preserve_order=True)
    model = get_spec().compile()
    data = mujoco.MjData(model)
    hinge_address = [model.jnt_qposadr[model.joint(name).id] for name in entity.joint_names]
    tracked_ids = [model.body(name).id for name in tracked]
    results = []
    for path in files:
        stored = np.load(path)
        loader = MotionLoader(path, torch.tensor(body_indexes, dtype=torch.long))
        frames = loader.time_step_total
        position_error = []
        rotation_error = []
        for t in np.linspace(0, frames - 1, SAMPLED_FRAMES).astype(int):
            data.qpos[:3] = loader._body_pos_w[t, 0].numpy()
            data.qpos[3:7] = loader._body_quat_w[t, 0].numpy()
            data.qpos[hinge_address] = loader.joint_pos[t].numpy()
            mujoco.mj_kinematics(model, data)
            position_error.append(np.linalg.norm(data.xpos[tracked_ids] - loader.body_pos_w[t].numpy(), axis=-1))
            difference = np.empty(3)
            for expected, loaded in zip(data.xquat[tracked_ids], loader.body_quat_w[t].numpy().astype(float)):
                mujoco.mju_subQuat(difference, expected, loaded)
                rotation_error.append(np.linalg.norm(difference))
        results.append(
            {
                "file": Path(path).name,
                "frames": frames,
                "fps": float(stored["fps"][0]),
                "joint_names_match": list(stored["joint_names"]) == list(entity.joint_names),
                "body_names_match": list(stored["body_names"]) == list(entity.body_names),
                "tracked_bodies": list(tracked),
                "body_pos_error_max_mm": round(float(np.max(position_error)) * 1000, 4),
                "body_rot_error_max_deg": round(float(np.degrees(np.max(rotation_error))), 6),
            }
        )
    return {
        "mjlab_entity_joints": len(entity.joint_names),
        "mjlab_entity_bodies": len(entity.body_names),
        "files": results,
    }


def export(motion: str, folder: Path) -> list[str]:
    files = []
    for source in ("bvh", "csv"):
        out = folder / f"g1_{motion}_{source}.npz"
        command = ["rd-pipeline", "export-motion", "--robot", "g1", "--motion", motion, "--source", source]
        subprocess.run([*command, "--format", "mjlab", "--out", str(out)], check=True)
        files.append(str(out))
    return files


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mjlab-python", help="python of a venv with mjlab 1.6 installed")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--check", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.check:
        print(json.dumps(check(args.check)))
        return
    if not args.mjlab_python:
        parser.error("--mjlab-python is required (see the module docstring)")
    with tempfile.TemporaryDirectory() as folder:
        files = export(args.motion, Path(folder))
        command = [args.mjlab_python, __file__, "--check", *files]
        finished = subprocess.run(command, check=True, capture_output=True, text=True)
    measured = json.loads(finished.stdout.strip().splitlines()[-1])
    version = subprocess.run(
        [args.mjlab_python, "-c", "import importlib.metadata as m; print(m.version('mjlab'))"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    result = {"mjlab": version, "robot": "g1", "motion": args.motion, **measured}
    RESULTS.write_text(json.dumps(result, indent=1) + "\n")
    json.dump(result, sys.stdout, indent=1)
    print(f"\nwrote {RESULTS}")


if __name__ == "__main__":
    main()
