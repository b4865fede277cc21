"""Benchmark and picture of the training collision model: fitted primitives against the MJCF meshes.

    python -m studies.collision_model [--robots g1 h1 h1_2] [--repeats 5] [--out studies/results/collision_model]

For each robot: a PNG of the fitted primitives (boxes, wireframe) over the collision meshes (grey
points) in the rest pose, from the front and the side; the covering statistics; and `mj_step`
steps/s of the mesh and the primitive model, interleaved, from reference poses of the dataset's
dance1_subject2 held by PD (standing) and after a push from the same poses (falls, bodies on the
floor). Results go to `<out>.json` and `<out>_<robot>.png`.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import mujoco
import numpy as np
import trimesh

from rd_pipeline import paths
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import load_robot
from rd_pipeline.robots.primitives import fit_collision_meshes, mesh_vertices_in_body


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["g1", "h1", "h1_2"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("studies/results/collision_model"))
    args = parser.parse_args()
    rows = []
    for name in args.robots:
        row = {"robot": name, **_fit_stats(name, args.out.parent / f"{args.out.name}_{name}.png")}
        row.update(_step_rates(name, args.repeats))
        rows.append(row)
        print(json.dumps(row), flush=True)
    args.out.with_suffix(".json").write_text(json.dumps(rows, indent=2) + "\n")


def _fit_stats(name: str, picture: Path) -> dict:
    robot = load_robot(name)
    config = robot.config
    model = simulation_model(robot, collision="mesh")
    shapes = fit_collision_meshes(model, tuple(model.body(b).id for b in config.foot_bodies))
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_forward(model, data)
    fig, axes = plt.subplots(1, 2, figsize=(10, 6), subplot_kw={"projection": "3d"})
    ratios = []
    for geom in sorted({shape.geom for shape in shapes}):
        body = int(model.geom_bodyid[geom])
        rotation = data.xmat[body].reshape(3, 3)
        vertices = mesh_vertices_in_body(model, geom)
        own = [shape for shape in shapes if shape.geom == geom]
        ratios.append(sum(s.volume() for s in own) / trimesh.convex.convex_hull(vertices).volume)
        world = vertices[:: max(1, len(vertices) // 150)] @ rotation.T + data.xpos[body]
        for ax in axes:
            ax.scatter(*world.T, s=1, c="0.6")
            for shape in own:
                for start, end in _box_edges(shape.pos, shape.quat, shape.size):
                    segment = np.stack([start, end]) @ rotation.T + data.xpos[body]
                    ax.plot(*segment.T, lw=0.7, c="tab:red")
    for ax, (elev, azim, title) in zip(axes, ((0, 0, "front"), (0, 90, "side"))):
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(f"{name}: {title}")
        ax.set_box_aspect((1, 1, 2.5))
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(picture, dpi=110)
    plt.close(fig)
    return {
        "meshes": len(ratios),
        "primitives": len(shapes),
        "volume_ratio_median": round(float(np.median(ratios)), 2),
        "volume_ratio_max": round(float(np.max(ratios)), 2),
        "picture": str(picture),
    }


def _box_edges(pos: np.ndarray, quat: np.ndarray, size: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    rotation = np.empty(9)
    mujoco.mju_quat2Mat(rotation, quat)
    corners = {
        signs: pos + rotation.reshape(3, 3) @ (np.array(signs) * size) for signs in itertools.product((-1, 1), repeat=3)
    }
    return [
        (corners[a], corners[b]) for a in corners for b in corners if sum(x != y for x, y in zip(a, b)) == 1 and a < b
    ]


def _step_rates(name: str, repeats: int) -> dict:
    robot = load_robot(name)
    reference = import_retargeted_csv(
        paths.csv_path(name, "dance1_subject2"), robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    models = {kind: simulation_model(robot, collision=kind) for kind in ("mesh", "primitive")}
    rates: dict[str, list[float]] = {}
    for _ in range(repeats):  # interleaved: both models see the same machine state
        for kind, model in models.items():
            for pushed in (False, True):
                rates.setdefault(f"{kind}_{'fallen' if pushed else 'standing'}", []).append(
                    _rate(robot, model, reference, pushed)
                )
    out = {f"steps_per_s_{key}": round(float(np.median(values))) for key, values in rates.items()}
    for case in ("standing", "fallen"):
        out[f"speedup_{case}"] = round(out[f"steps_per_s_primitive_{case}"] / out[f"steps_per_s_mesh_{case}"], 2)
    return out


def _rate(robot, model: mujoco.MjModel, reference, pushed: bool) -> float:
    data = mujoco.MjData(model)
    joints = [model.jnt_qposadr[model.joint(j).id] for j in robot.config.joint_names]
    seconds = 0.0
    steps = 0
    for frame in range(0, 1000, 100):
        mujoco.mj_resetData(model, data)
        data.qpos[:3] = reference.root_pos[frame]
        data.qpos[3:7] = reference.root_quat[frame]
        data.qpos[joints] = reference.joint_pos[frame]
        if pushed:
            data.qvel[:2] = (2.0, 1.0)  # a shove that puts most of the body on the floor
            data.ctrl[:] = reference.joint_pos[frame]
            mujoco.mj_step(model, data, nstep=500)
        began = time.perf_counter()
        for k in range(20):
            data.ctrl[:] = reference.joint_pos[frame + k // 5]
            mujoco.mj_step(model, data, nstep=10)
        seconds += time.perf_counter() - began
        steps += 200
    return steps / seconds


if __name__ == "__main__":
    main()
