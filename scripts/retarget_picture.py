"""A retargeted take beside the human: a filmstrip PNG of the LAFAN1 skeleton and the robot's reference.

    python -m scripts.retarget_picture --robot g1 --motion dance1_subject2 \
        --out docs/images/retarget_g1_dance1_subject2.png [--times 67 69 70 71 72 73.5]

Plans the (robot, motion) pair on the cpu profile and runs it up to retarget (a store that holds
those artifacts reuses them). Each time is one frame rendered headless by MuJoCo: the robot's
meshes in its own colours, the human's bones as orange capsules in the same scene beside it, on a
light floor, the camera in front of the robot. MuJoCo picks its OpenGL backend when it is imported,
so the frames are rendered in a process of their own with `MUJOCO_GL` set (EGL, else OSMesa), as
`rd_pipeline.viz.render` does.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.viz.render import render_in_child

if TYPE_CHECKING:
    # Imported where it renders: this process's MuJoCo is not the one `MUJOCO_GL` chose.
    import mujoco

DEFAULT_TIMES = (67.0, 69.0, 70.0, 71.0, 72.0, 73.5)
"""A lively stretch of dance1_subject2: kicks, lunges, both arms up, a deep crouch."""
RENDER_TIMEOUT_S = 600.0
"""How long the child may take to render every frame."""
FRAMES_FILE = "frames.npz"
META_FILE = "frames.json"
WIDTH, HEIGHT = 340, 400
GAP_M = 0.9
"""How far the human stands to the robot's left, as the camera sees them."""
AZIMUTH_OFF_FRONT_DEG = 20.0
"""A three-quarter view rather than straight on, so depth reads."""
HUMAN_RGBA = np.array([1.0, 0.5, 0.1, 1.0], dtype=np.float32)
BONE_RADIUS_M = 0.028
HEAD_RADIUS_M = 0.09


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    parser.add_argument("--times", type=float, nargs="+", default=list(DEFAULT_TIMES), help="seconds into the take")
    parser.add_argument("--profile", default="cpu")
    # The rendering child's entry: a folder of prepared frames.
    parser.add_argument("--render-from", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.render_from is not None:
        _render(args.render_from, args.out)
        return
    try:
        with tempfile.TemporaryDirectory() as work:
            _prepare(args.robot, args.motion, args.profile, args.times, Path(work))
            _render_headless(Path(work), args.out)
    except PipelineError as exc:
        sys.exit(f"error: {exc}")
    print(f"{args.out} ({args.out.stat().st_size / 1024:.0f} KiB)")


# --- the parent: the pipeline's artifacts, sampled at the chosen times ---


def _prepare(robot: str, motion: str, profile: str, times: list[float], work: Path) -> None:
    """Run (or reuse) the pipeline up to retarget and write the poses at `times` into `work`."""
    from rd_pipeline.api import workspace
    from rd_pipeline.motion.human import HUMAN_MOTION_FILE, HumanMotion
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion

    plan = workspace.plan(robot, motion, profile=profile)
    workspace.run(plan, until="retarget")
    human = HumanMotion.load(workspace.required_artifact(plan, "parse") / HUMAN_MOTION_FILE)
    reference = ReferenceMotion.load(workspace.required_artifact(plan, "retarget") / REFERENCE_FILE)
    end_s = min(human.duration_s, reference.duration_s)
    if not all(0.0 <= t < end_s for t in times):
        raise PipelineError(f"--times must lie within the take's {end_s:.1f} s")
    human_frames = _frame_indices(times, human.fps, human.n_frames)
    robot_frames = _frame_indices(times, reference.fps, reference.n_frames)
    np.savez(
        work / FRAMES_FILE,
        times=np.array(times),
        human_pos=human.pos_w[human_frames],
        human_parents=human.parents,
        root_pos=reference.root_pos[robot_frames],
        root_quat=reference.root_quat[robot_frames],
        joint_pos=reference.joint_pos[robot_frames],
    )
    meta = {"robot": robot, "motion": motion, "human_names": list(human.names)}
    (work / META_FILE).write_text(json.dumps(meta))


def _frame_indices(times: list[float], fps: float, count: int) -> np.ndarray:
    return np.clip(np.round(np.array(times) * fps).astype(int), 0, count - 1)


def _render_headless(work: Path, out: Path) -> None:
    """Render in a child process per OpenGL backend until one works."""
    command = [sys.executable, "-m", "scripts.retarget_picture", "--render-from", str(work), "--out", str(out)]
    why = render_in_child(command, RENDER_TIMEOUT_S)
    if why:
        raise PipelineError(f"could not render: {why}")


# --- the child: MuJoCo with the backend `MUJOCO_GL` chose ---


def _render(work: Path, out: Path) -> None:
    """The filmstrip of the frames `_prepare` wrote into `work`, into `out`."""
    from rd_pipeline.robots import load_robot

    meta = json.loads((work / META_FILE).read_text())
    frames = np.load(work / FRAMES_FILE)
    robot = load_robot(meta["robot"])
    painter = _Painter(robot.model, frames["human_parents"], meta["human_names"])
    images = []
    for k in range(len(frames["times"])):
        qpos = robot.model.qpos0.copy()
        qpos[:3] = frames["root_pos"][k]
        qpos[3:7] = frames["root_quat"][k] / np.linalg.norm(frames["root_quat"][k])
        qpos[robot.qpos_indices] = frames["joint_pos"][k]
        images.append(painter.view(qpos, frames["human_pos"][k]))
    robot_name = robot.config.description.split(":")[0]
    title = f"LAFAN1 {meta['motion']}: the human (orange) and its retarget onto {robot_name}"
    _filmstrip(images, frames["times"], title, out)


class _Painter:
    """One offscreen view of the robot with the human skeleton drawn beside it as user geoms."""

    def __init__(self, model: mujoco.MjModel, parents: np.ndarray, names: list[str]) -> None:
        import mujoco

        self.mujoco = mujoco
        self.model = model
        self.parents = parents
        self.head = names.index("Head")
        self.hips = names.index("Hips")
        _lighten(model)
        self.data = mujoco.MjData(model)
        self.renderer = mujoco.Renderer(model, HEIGHT, WIDTH)
        self.camera = mujoco.MjvCamera()
        self.camera.distance = 3.1
        self.camera.elevation = -12.0

    def view(self, qpos: np.ndarray, human_pos: np.ndarray) -> np.ndarray:
        """(HEIGHT, WIDTH, 3): the robot at `qpos`, seen from its front, and the human to its left."""
        mujoco = self.mujoco
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        azimuth = np.degrees(_yaw(qpos[3:7])) + 180.0 + AZIMUTH_OFF_FRONT_DEG
        right = np.array([np.sin(np.radians(azimuth)), -np.cos(np.radians(azimuth)), 0.0])
        # The human stands on the robot's spot, shifted left on screen; its own path is not the point here.
        shift = np.array([*(qpos[:2] - human_pos[self.hips, :2]), 0.0]) - GAP_M * right
        human = human_pos + shift
        self.camera.azimuth = azimuth
        self.camera.lookat[:] = [*(qpos[:2] - GAP_M / 2 * right[:2]), 0.8]
        self.renderer.update_scene(self.data, self.camera)
        self._add_skeleton(self.renderer.scene, human)
        return self.renderer.render().copy()

    def _add_skeleton(self, scene: mujoco.MjvScene, joints: np.ndarray) -> None:
        mujoco = self.mujoco
        for child, parent in enumerate(self.parents):
            if parent >= 0:
                geom = _new_geom(scene, mujoco.mjtGeom.mjGEOM_CAPSULE, joints[child], BONE_RADIUS_M)
                mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, BONE_RADIUS_M, joints[parent], joints[child])
            _new_geom(scene, mujoco.mjtGeom.mjGEOM_SPHERE, joints[child], BONE_RADIUS_M * 1.4)
        # The head joint sits at the neck's top: the head's ball a little above it.
        head = joints[self.head] + np.array([0.0, 0.0, 0.07])
        _new_geom(scene, mujoco.mjtGeom.mjGEOM_SPHERE, head, HEAD_RADIUS_M)


def _new_geom(scene: mujoco.MjvScene, kind: int, pos: np.ndarray, radius: float) -> mujoco.MjvGeom:
    import mujoco

    if scene.ngeom >= scene.maxgeom:
        raise PipelineError("the scene has no room left for the human's geoms")
    geom = scene.geoms[scene.ngeom]
    size = np.array([radius, radius, radius])
    mujoco.mjv_initGeom(geom, kind, size, pos.astype(float), np.eye(3).ravel(), HUMAN_RGBA)
    scene.ngeom += 1
    return geom


def _lighten(model: mujoco.MjModel) -> None:
    """A light floor and sky and a brighter headlight: the robots' MJCFs bring a dark stage."""
    import mujoco

    model.vis.headlight.ambient[:] = 0.45
    model.vis.headlight.diffuse[:] = 0.6
    model.vis.rgba.haze[:] = [0.95, 0.95, 0.95, 1.0]
    planes = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    floors = np.unique(model.geom_matid[planes & (model.geom_matid >= 0)])
    # A mirror floor doubles every figure; a faint glow keeps it light away from the headlight.
    model.mat_reflectance[floors] = 0.0
    model.mat_emission[floors] = 0.35
    for tex in np.unique(model.mat_texid[floors]):
        if tex >= 0:
            # Inverted to grey: the dark checker turns light and its light edge marks turn grey lines.
            _repaint(model, int(tex), lambda rgb: 245.0 - 0.5 * rgb.mean(axis=1, keepdims=True))
    for tex in np.flatnonzero(model.tex_type == mujoco.mjtTexture.mjTEXTURE_SKYBOX):
        _repaint(model, int(tex), lambda rgb: np.full_like(rgb, 245.0))


def _repaint(model: mujoco.MjModel, tex: int, paint: Callable[[np.ndarray], np.ndarray]) -> None:
    """Texture `tex`'s colour channels through `paint` ((pixels, 3) floats 0-255), alpha kept."""
    start = model.tex_adr[tex]
    channels = model.tex_nchannel[tex]
    size = model.tex_width[tex] * model.tex_height[tex] * channels
    pixels = model.tex_data[start : start + size].reshape(-1, channels).astype(float)
    pixels[:, :3] = paint(pixels[:, :3])
    model.tex_data[start : start + size] = np.clip(pixels, 0, 255).ravel().astype(np.uint8)


def _yaw(quat_wxyz: np.ndarray) -> float:
    w, x, y, z = quat_wxyz
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def _filmstrip(images: list[np.ndarray], times: np.ndarray, title: str, out: Path) -> None:
    """The frames in one row, each captioned with its time, under one title line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    count = len(images)
    dpi = 100
    fig, axes = plt.subplots(1, count, figsize=(count * WIDTH / dpi, HEIGHT / dpi + 0.55), squeeze=False)
    for ax, image, t in zip(axes.flat, images, times):
        ax.imshow(image)
        ax.axis("off")
        ax.set_title(f"t = {t:.1f} s", fontsize=10)
    fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.005, right=0.995, bottom=0.005, top=0.86, wspace=0.02)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    plt.close(fig)
    # 256 colours hold these flat shades well and keep the README's picture small.
    picture = Image.open(buffer).convert("RGB").quantize(colors=256, dither=Image.Dither.NONE)
    out.parent.mkdir(parents=True, exist_ok=True)
    picture.save(out, optimize=True)


if __name__ == "__main__":
    main()
