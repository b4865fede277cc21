"""Pictures of a rollout beside its reference: a filmstrip PNG and a short MP4, rendered headless.

MuJoCo picks its OpenGL backend when it is imported, so the pictures are rendered in a process of
their own with `MUJOCO_GL` set (EGL, else OSMesa): the caller's MuJoCo stays as it was, and a
machine without either gets one line saying why instead of a crash.

    python -m rd_pipeline.viz.render <scene.npz> <out folder>
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rd_pipeline.files import write_bytes_whole
from rd_pipeline.viz.render_config import RenderConfig

if TYPE_CHECKING:
    # Imported where it renders: this process's MuJoCo is not the one `MUJOCO_GL` chose.
    import mujoco

FILMSTRIP_FILE = "filmstrip.png"
VIDEO_FILE = "rollout.mp4"
SCENE_FILE = "scene.npz"
MODEL_FILE = "scene.mjb"
GL_BACKENDS = ("egl", "osmesa")
REFERENCE_RGBA = (0.25, 0.55, 1.0, 0.45)
"""The reference robot: translucent blue, so the tracked robot (its own colours) stands out."""


@dataclass(frozen=True)
class Scene:
    """What the pictures show: one rollout and its reference, frame by frame at the control rate."""

    title: str
    """Robot, motion and policy, for the filmstrip's heading."""
    tracked: np.ndarray
    """(steps + 1, nq) the rollout's generalized positions."""
    reference: np.ndarray
    """(frames, nq) the reference's, from the rollout's start frame on."""
    control_hz: float
    ended_by: str
    """What ended the rollout ("" if it reached the clip's end)."""


def render_pictures(model: mujoco.MjModel, scene: Scene, look: RenderConfig, out_dir: Path) -> dict[str, str]:
    """Render `scene` of the compiled MuJoCo `model` into `out_dir`: {"filmstrip", "video"} file
    names, or {"skipped": why} where no offscreen OpenGL works here."""
    import mujoco

    work = out_dir / ".render"
    work.mkdir(exist_ok=True)
    # Through memory: MuJoCo's own file writer does not report a full disk.
    binary = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, binary)
    write_bytes_whole(work / MODEL_FILE, binary.tobytes())
    np.savez(work / SCENE_FILE, tracked=scene.tracked, reference=scene.reference)
    meta = {**asdict(look), "title": scene.title, "control_hz": scene.control_hz, "ended_by": scene.ended_by}
    (work / "scene.json").write_text(json.dumps(meta))
    command = [sys.executable, "-m", "rd_pipeline.viz.render", str(work), str(out_dir)]
    try:
        why = render_in_child(command, look.timeout_s)
    except subprocess.TimeoutExpired:
        why = f"rendering took over {look.timeout_s:g} s"
    finally:
        for path in work.iterdir():
            path.unlink()
        work.rmdir()
    return {"skipped": why} if why else {"filmstrip": FILMSTRIP_FILE, "video": VIDEO_FILE}


def render_in_child(command: list[str], timeout_s: float) -> str | None:
    """Run `command` (a renderer) once per OpenGL backend until one works: None then, else why
    the last one failed. Each try is a process of its own, as MuJoCo picks its backend at import."""
    why = "no offscreen OpenGL"
    for backend in GL_BACKENDS:
        env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
        done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=timeout_s, check=False)
        if done.returncode == 0:
            return None
        lines = done.stderr.strip().splitlines() or [f"exit {done.returncode}"]
        why = f"MUJOCO_GL={backend}: {lines[-1]}"
    return why


def _main(work: Path, out_dir: Path) -> None:
    import mujoco

    meta = json.loads((work / "scene.json").read_text())
    arrays = np.load(work / SCENE_FILE)
    model = mujoco.MjModel.from_binary_path(str(work / MODEL_FILE))
    look = RenderConfig(**{name: meta[name] for name in RenderConfig.__dataclass_fields__})
    scene = Scene(meta["title"], arrays["tracked"], arrays["reference"], meta["control_hz"], meta["ended_by"])
    painter = _Painter(model, look)
    _filmstrip(painter, scene, look, out_dir / FILMSTRIP_FILE)
    _video(painter, scene, look, out_dir / VIDEO_FILE)


class _Painter:
    """One offscreen view of the tracked robot with the reference drawn beside it."""

    def __init__(self, model: mujoco.MjModel, look: RenderConfig) -> None:
        import mujoco

        self.mujoco = mujoco
        self.model = model
        self.look = look
        # The robots' MJCFs bring no lights: a brighter headlight shows their shapes.
        model.vis.headlight.ambient[:] = 0.45
        model.vis.headlight.diffuse[:] = 0.6
        model.vis.quality.offsamples = look.multisamples
        self.tracked = mujoco.MjData(model)
        self.reference = mujoco.MjData(model)
        self.renderer = mujoco.Renderer(model, look.height, look.width)
        self.camera = mujoco.MjvCamera()
        self.camera.distance = 3.8
        self.camera.elevation = -18.0
        self.camera.azimuth = 150.0
        self.option = mujoco.MjvOption()
        self.perturb = mujoco.MjvPerturb()

    def view(self, tracked_qpos: np.ndarray | None, reference_qpos: np.ndarray) -> np.ndarray:
        """(height, width, 3) the tracked pose (None: none, its rollout has ended) and the reference
        pose `beside_m` to its left, the camera following the reference."""
        mujoco = self.mujoco
        self.reference.qpos[:] = reference_qpos
        self.reference.qpos[1] += self.look.beside_m
        if tracked_qpos is None:
            # Out of sight below the floor: the scene then shows the reference alone.
            self.tracked.qpos[:] = reference_qpos
            self.tracked.qpos[2] -= 100.0
        else:
            self.tracked.qpos[:] = tracked_qpos
        mujoco.mj_kinematics(self.model, self.tracked)
        mujoco.mj_kinematics(self.model, self.reference)
        self.camera.lookat[:] = reference_qpos[:3]
        self.camera.lookat[1] += self.look.beside_m / 2
        self.camera.lookat[2] = 0.7
        self.renderer.update_scene(self.tracked, self.camera)
        scene = self.renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.look.shadows
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = self.look.shadows
        first = scene.ngeom
        mujoco.mjv_addGeoms(
            self.model, self.reference, self.option, self.perturb, mujoco.mjtCatBit.mjCAT_DYNAMIC, scene
        )
        for k in range(first, scene.ngeom):
            scene.geoms[k].rgba[:] = REFERENCE_RGBA
            scene.geoms[k].matid = -1
        return self.renderer.render().copy()


def _pose_at(scene: Scene, step: int) -> tuple[np.ndarray | None, np.ndarray]:
    """The tracked (None once its rollout has ended) and reference poses at control step `step`."""
    tracked = scene.tracked[step] if step < len(scene.tracked) else None
    return tracked, scene.reference[min(step, len(scene.reference) - 1)]


def filmstrip_steps(scene: Scene, count: int) -> np.ndarray:
    """`count` control steps evenly spaced over the clip, the rollout's last one among them when it
    ended early (in place of the nearest)."""
    steps = np.linspace(0, len(scene.reference) - 1, count).round().astype(int)
    end = len(scene.tracked) - 1
    if scene.ended_by and end not in steps:
        # The nearest later view gives way, so the clip's first frame always shows.
        steps[max(1, int(np.searchsorted(steps, end)))] = end
    return np.unique(steps)


def _end_line(scene: Scene) -> str:
    seconds = (len(scene.tracked) - 1) / scene.control_hz
    if not scene.ended_by:
        return f"reached the clip's end ({seconds:.2f} s)"
    return f"ended at {seconds:.2f} s: {scene.ended_by}"


def _filmstrip(painter: _Painter, scene: Scene, look: RenderConfig, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = filmstrip_steps(scene, look.filmstrip_frames)
    count = len(steps)
    columns = min(count, 3)
    rows = -(-count // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows + 0.6), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, step in zip(axes.flat, steps):
        tracked, reference = _pose_at(scene, step)
        ax.imshow(painter.view(tracked, reference))
        label = f"t = {step / scene.control_hz:.2f} s"
        if step == len(scene.tracked) - 1 and scene.ended_by:
            ax.set_title(f"{label}: ended ({scene.ended_by})", color="red", fontsize=9)
        elif tracked is None:
            ax.set_title(f"{label}: reference alone", color="gray", fontsize=9)
        else:
            ax.set_title(label, fontsize=9)
    fig.suptitle(f"{scene.title}\ntracked robot (grey) beside its reference (blue); {_end_line(scene)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _video(painter: _Painter, scene: Scene, look: RenderConfig, path: Path) -> None:
    import imageio_ffmpeg
    from PIL import Image, ImageDraw

    stride = max(1, round(scene.control_hz / look.video_fps))
    # One second past the end shows how it ended; `video_max_s` keeps a long rollout's video short.
    end = min(
        len(scene.reference), len(scene.tracked) + round(scene.control_hz), round(look.video_max_s * scene.control_hz)
    )
    writer = imageio_ffmpeg.write_frames(
        str(path), (look.width, look.height), fps=scene.control_hz / stride, quality=7, macro_block_size=8
    )
    writer.send(None)
    for step in range(0, max(end, 1), stride):
        tracked, reference = _pose_at(scene, step)
        image = Image.fromarray(painter.view(tracked, reference))
        draw = ImageDraw.Draw(image)
        draw.text((8, 6), f"t = {step / scene.control_hz:.2f} s   blue: reference", fill=(255, 255, 255))
        if tracked is None:
            draw.text((8, 22), _end_line(scene), fill=(200, 0, 0))
        writer.send(np.ascontiguousarray(np.asarray(image)).tobytes())
    writer.close()


if __name__ == "__main__":
    _main(Path(sys.argv[1]), Path(sys.argv[2]))
