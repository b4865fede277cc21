"""Study: a floor cut's feet learnt from the plants made standing, against every plant, as a picture.

    python -m studies.foot_calibration [--robot g1] [--take ground2_subject2] [--start 145] [--end 165]
                                       [--out docs/images/foot_calibration_g1_ground2_subject2.png]

The robot foot's orientation target is the human foot joint's, turned by one offset that lays it
flat, learnt from the clip's plants (retarget stage 23: from the plants made standing). The cut
is shaped both ways, the old rule by counting no frame as standing, and plotted over its
seconds: each rule's foot targets against the same frames' targets inside the whole take, and
the retargeted pelvis height against the scaled human's (the pelvis ruler, bar 0.10 m).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.spatial.transform import Rotation

from bench.retarget_variants import BARS, clips, floor_cut, pelvis_deviation
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig, TargetShaping
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.retarget.targets import RetargetTargets, build_targets
from rd_pipeline.robots import Robot, load_robot

FPS = 50.0
"""The retargeter's output rate."""
EVERY_PLANT = dataclasses.replace(TargetShaping(), standing_hips_fraction=10.0, upright_shin_fraction=10.0)
"""No frame counts as standing or the shin as upright, so the feet are learnt from every plant (the
rule before stage 23)."""


def foot_turn_from_whole_take(
    robot: Robot,
    take: str,
    seconds: tuple[int, int],
    shape: TargetShaping,
) -> np.ndarray:
    """(T, 2) degrees, per frame and foot, between the cut's foot targets (shaped by `shape`) and
    the same frames' targets inside the whole take (default shaping)."""
    whole = _targets(robot, clips(take, "plain")[0][1], TargetShaping())
    cut = _targets(robot, _cut(take, seconds), shape)
    start = int(seconds[0] * FPS)
    frames = slice(start, start + cut.n_frames)
    turns = []
    for foot in robot.config.foot_bodies:
        in_whole = Rotation.from_matrix(whole.orientations[foot][frames])
        in_cut = Rotation.from_matrix(cut.orientations[foot])
        turns.append(np.degrees((in_whole.inv() * in_cut).magnitude()))
    return np.stack(turns, axis=1)


def _targets(robot: Robot, clip: HumanMotion, shape: TargetShaping) -> RetargetTargets:
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    return build_targets(clip, robot, FPS, vertices, params.contact, shape, params.body_contact)


def _cut(take: str, seconds: tuple[int, int]) -> HumanMotion:
    return floor_cut(take, f"{take} {seconds[0]}-{seconds[1]} s")


def _pelvis_deviation(robot: Robot, clip: HumanMotion, shape: TargetShaping) -> np.ndarray:
    """(T,) the pelvis ruler's per-frame deviation (m) of the clip retargeted with `shape`."""
    return pelvis_deviation(robot, retarget(clip, robot, dataclasses.replace(RetargetConfig(), shape=shape)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--take", default="ground2_subject2")
    parser.add_argument("--start", type=int, default=145)
    parser.add_argument("--end", type=int, default=165)
    parser.add_argument("--out", type=Path, default=Path("docs/images/foot_calibration_g1_ground2_subject2.png"))
    args = parser.parse_args()
    seconds = (args.start, args.end)
    rules = {"plants made standing (stage 23)": TargetShaping(), "every plant (stage 22)": EVERY_PLANT}
    try:
        robot = load_robot(args.robot)
        clip = _cut(args.take, seconds)
        turns = {rule: foot_turn_from_whole_take(robot, args.take, seconds, shape) for rule, shape in rules.items()}
        pelvis = {rule: _pelvis_deviation(robot, clip, shape) for rule, shape in rules.items()}
    except PipelineError as exc:
        raise SystemExit(f"foot_calibration: {exc}") from None
    _plot(args, turns, pelvis)
    print(f"wrote {args.out}")


def _plot(args: argparse.Namespace, turns: dict, pelvis: dict) -> None:
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for (rule, turn), colour in zip(turns.items(), ("tab:green", "tab:red")):
        time = args.start + np.arange(len(turn)) / FPS
        top.plot(time, turn[:, 0], color=colour, label=f"{rule}, left foot")
        top.plot(time, turn[:, 1], color=colour, alpha=0.4, label=f"{rule}, right foot")
        deviation = pelvis[rule]
        p95 = np.percentile(np.abs(deviation), 95)
        bottom.plot(time, deviation, color=colour, label=f"{rule}: p95 {p95:.3f} m")
    top.set_ylabel("foot target vs whole take (deg)")
    top.legend(fontsize=8)
    bar = BARS["pelvis_height_dev_p95_m"]
    for level in (-bar, bar):
        bottom.axhline(level, color="grey", linestyle="--", linewidth=0.8)
    bottom.set_ylabel("pelvis - scaled human (m)")
    bottom.set_xlabel(f"{args.take} (s)")
    bottom.legend(fontsize=8)
    figure.suptitle(f"{args.robot} {args.take} {args.start}-{args.end} s: the feet learnt from which plants")
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
