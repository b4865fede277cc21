"""Frame-by-frame IK with mink: key-body frame tasks, posture regularization, hard limits, warm start."""

from __future__ import annotations

import ctypes
from collections import deque
from collections.abc import Iterable

import daqp
import mink
import mujoco
import numpy as np
import qpsolvers
from scipy.ndimage import maximum_filter1d
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.retarget.collision import collision_limit
from rd_pipeline.retarget.config import IkConfig, IkWeights
from rd_pipeline.retarget.floor import FloorLimit
from rd_pipeline.retarget.limits import FrameStepLimit
from rd_pipeline.retarget.start_postures import start_postures
from rd_pipeline.retarget.targets import RetargetTargets
from rd_pipeline.retarget.tasks import key_bodies_task, position_cost_schedule, posture_task, target_poses
from rd_pipeline.robots import Robot
from rd_pipeline.robots.hulls import BodyHulls
from rd_pipeline.robots.model import collision_geom_pairs


class RetargetIk:
    """One mink problem reused for every frame."""

    def __init__(
        self,
        robot: Robot,
        targets: RetargetTargets,
        weights: IkWeights,
        settings: IkConfig,
        hulls: BodyHulls,
    ) -> None:
        if settings.solver not in qpsolvers.available_solvers:
            installed = ", ".join(sorted(qpsolvers.available_solvers))
            raise PipelineError(f"retarget.ik.solver '{settings.solver}' is not an installed QP solver ({installed})")
        self.robot = robot
        self.targets = targets
        self.settings = settings
        model = robot.model
        config = robot.config
        self.configuration = mink.Configuration(model)
        self.key_bodies = key_bodies_task(robot, targets, weights, settings.lm_damping)
        self.position_costs = position_cost_schedule(targets, config, weights)
        self.applied_costs: np.ndarray | None = None
        self.posture = posture_task(robot, self.configuration, weights.posture)
        self.step_limit = _frame_step_limit(robot, targets.fps, settings.velocity_margin)
        self.root_steps = _root_step_budget(targets, config.root_body, settings)
        self.floor = FloorLimit(
            model,
            hulls,
            settings.floor_clearance_m,
            settings.floor_detection_m,
            settings.floor_support_reuse,
        )
        self.floor_raise = _swing_floor_raise(targets, hulls, config.foot_bodies, settings.swing_floor_fraction)
        self.collision_pairs = collision_geom_pairs(robot)
        self.pair_reach_squared = model.geom_rbound[self.collision_pairs].sum(axis=1) ** 2
        self.depth_known_at: tuple[np.ndarray, float] | None = None
        self.frame = 0  # the frame being solved, named when no step is found
        avoidance = collision_limit(robot, settings)
        self.limits: list[mink.Limit] = [self.step_limit, self.floor]
        if avoidance is not None:
            self.limits.append(avoidance)
        self.tasks = [self.key_bodies, self.posture]
        self.damping = weights.damping
        self.key_body_ids = np.array(self.key_bodies.body_ids)
        self.target_poses = target_poses(targets)
        self.start_postures = start_postures(robot, settings.start_knee_bends)

    def initial_configuration(self, joints: np.ndarray) -> np.ndarray:
        """The posture `joints` (config order) placed at the first frame's pelvis target."""
        q = np.zeros(self.robot.model.nq)
        q[3] = 1.0
        q[self.robot.qpos_indices] = joints
        root = self.targets.bodies.index(self.robot.config.root_body)
        q[:3] = self.targets.positions[0, root]
        rotation = self.targets.orientations.get(self.robot.config.root_body)
        if rotation is not None:
            mujoco.mju_mat2Quat(q[3:7], rotation[0].reshape(-1))
        # A take that starts on the floor must not start below it.
        self.configuration.update(q)
        lowest, _ = self.floor.lowest_points(self.configuration.data)
        q[2] += max(0.0, self.settings.floor_clearance_m - float(lowest.min()))
        return q

    def _set_frame_targets(self, t: int) -> None:
        self.frame = t
        self.floor.raise_bodies(self.floor_raise[t])
        # Frames are visited in any order (the lag repair solves backward), so the costs to compare
        # with are the ones the tasks hold, not the previous frame's.
        frame_costs = self.position_costs[t]
        if self.applied_costs is None or np.any(frame_costs != self.applied_costs):
            self.key_bodies.set_position_costs(frame_costs)
            self.applied_costs = frame_costs
        self.key_bodies.set_targets(self.target_poses[t])

    def refine_feet(
        self,
        smoothed: np.ndarray,
        frames: Iterable[int],
        root_slack_m: float = 0.0,
        start: np.ndarray | None = None,
    ) -> np.ndarray:
        """Put the feet of a smoothed trajectory back on their targets in `frames`, moving the joints
        (and the pelvis by up to `root_slack_m` per axis of its position; by default the base stays
        fixed). Rows not in `frames` are copied from `start` (default: `smoothed`).

        Each frame starts from the smoothed pose, with a posture task holding every joint near its
        smoothed value and a task holding the pelvis at its smoothed position, so the smoothness
        survives where the feet need no help.
        """
        config = self.robot.config
        columns = [self.targets.bodies.index(foot) for foot in config.foot_bodies]
        feet = self.key_bodies.select(columns)
        hold = mink.PostureTask(self.robot.model, cost=self.settings.refine_posture_cost)
        tasks: list[mink.Task] = [feet, hold]
        pelvis = None
        if root_slack_m > 0:
            pelvis = mink.FrameTask(config.root_body, "body", self.settings.refine_posture_cost, 0.0)
            tasks.append(pelvis)
        root_step = np.concatenate([np.full(3, root_slack_m), np.zeros(3)])
        joints = self.robot.qpos_indices
        correction_step = self.settings.refine_correction_rate / self.targets.fps
        out = (smoothed if start is None else start).copy()
        for t in frames:
            self._set_frame_targets(t)
            feet.set_targets(self.key_bodies.targets[columns])
            feet.set_position_costs(self.key_bodies.body_costs[columns, :3])
            hold.set_target(smoothed[t])
            self.configuration.update(smoothed[t])
            if pelvis is not None:
                pelvis.set_target_from_configuration(self.configuration)
            previous = out[t - 1] if t > 0 else None
            self.step_limit.start_frame(previous, root_step)
            if previous is not None:
                # The correction to the smoothed pose changes gradually: a leg near straight must
                # not flip to reach a foot target in one frame and back in the next.
                carried = smoothed[t, joints] + previous[joints] - smoothed[t - 1, joints]
                self.step_limit.narrow(carried - correction_step, carried + correction_step)
            for _ in range(self.settings.refine_iterations):
                self._iterate(tasks)
            out[t] = self._checked_clip(smoothed[t])
        return out

    def _checked_clip(self, fallback: np.ndarray) -> np.ndarray:
        """The current pose clipped into the frame's joint bounds, or `fallback` where the clip
        (which no collision check saw) pushes a configured body pair past the hard depth limit.

        A refinement that starts outside its narrowed bounds is clipped back into them after its
        iteration; on G1 ground2_subject3 that put a knee 6 mm into the other leg."""
        q = self.configuration.q
        clipped = self._clipped(q)
        if np.array_equal(clipped, q):
            return clipped
        self.configuration.update(clipped)
        if self._pair_depth() > self.settings.pair_depth_limit_m:
            return fallback.copy()
        return clipped

    def planted_foot_misses(self, qpos: np.ndarray) -> np.ndarray:
        """(T,) how far (m) the farthest planted foot of each row of `qpos` is from its target (0 when
        no foot is planted)."""
        feet = self.robot.config.foot_bodies
        columns = [self.targets.bodies.index(foot) for foot in feet]
        body_ids = [self.robot.body_ids[foot] for foot in feet]
        misses = np.zeros(len(qpos))
        for t, q in enumerate(qpos):
            planted = self.targets.foot_contact[t].astype(bool)
            if not planted.any():
                continue
            self.configuration.update(q)
            gap = self.configuration.data.xpos[body_ids] - self.targets.positions[t, columns]
            misses[t] = np.linalg.norm(gap, axis=1)[planted].max()
        return misses

    def _keypoint_error(self, t: int) -> float:
        """Mean distance of the key bodies to their targets in the current configuration."""
        positions = self.configuration.data.xpos[self.key_body_ids]
        return float(np.linalg.norm(positions - self.targets.positions[t], axis=1).mean())

    def _iterate(self, tasks: list[mink.Task]) -> None:
        """One solver step, shortened while it would push a configured body pair deeper into contact.

        The collision limit is linear in the closest points' normal; a large step that turns
        interlocking meshes (crossing knees) can still pass through, so the step is checked.
        """
        start = self.configuration.q.copy()
        before = self._pair_depth()
        velocity = self._step(tasks)
        for halving in range(self.settings.step_halvings + 1):
            self.configuration.integrate_inplace(velocity, 1.0)
            depth = self._pair_depth()
            if depth <= max(before, self.settings.pair_depth_tolerance_m):
                break
            # The shortest step is kept while the pair stays shallower than the hard limit: a pose
            # already touching must still be able to move, or the solve freezes there.
            if halving == self.settings.step_halvings and depth <= self.settings.pair_depth_limit_m:
                break
            self.configuration.update(start)
            velocity = 0.5 * velocity
        else:
            velocity = np.zeros_like(velocity)
        self.step_limit.spend_root_step(velocity[:6])

    def _pair_depth(self) -> float:
        """How deep the configured body pairs interpenetrate (m; 0 when none touch)."""
        q = self.configuration.q
        # An iteration starts where the last one ended: its depth is known.
        if self.depth_known_at is not None and np.array_equal(q, self.depth_known_at[0]):
            return self.depth_known_at[1]
        depth = self._measure_pair_depth()
        self.depth_known_at = (q.copy(), depth)
        return depth

    def _measure_pair_depth(self) -> float:
        data = self.configuration.data
        pairs = self.collision_pairs
        if len(pairs) == 0:
            return 0.0
        gap = data.geom_xpos[pairs[:, 0]] - data.geom_xpos[pairs[:, 1]]
        # Bounding spheres overlap; a pair they keep apart cannot touch, whatever the rounding.
        candidates = pairs[np.einsum("ij,ij->i", gap, gap) < self.pair_reach_squared]
        distances = [mujoco.mj_geomDistance(self.robot.model, data, a, b, 0.0, None) for a, b in candidates.tolist()]
        return max(0.0, -min(distances, default=0.0))

    def _step(self, tasks: list[mink.Task]) -> np.ndarray:
        """One QP step; if climbing back above the floor clearance is infeasible with the frame's
        bounds, take the step that only stops the sinking."""
        try:
            return self._solve_qp(tasks)
        except mink.NoSolutionFound:
            self.floor.relaxed = True
            try:
                return self._solve_qp(tasks)
            except mink.NoSolutionFound:
                raise PipelineError(
                    f"retarget: QP solver '{self.settings.solver}' found no step at frame {self.frame}, "
                    "even with the floor clearance relaxed"
                ) from None
            finally:
                self.floor.relaxed = False

    def _solve_qp(self, tasks: list[mink.Task]) -> np.ndarray:
        """mink.solve_ik, less its check of the model's joint ranges (it only logs; the step limit
        keeps the joints in the config's range), and less the rows with an infinite bound. mink's
        collision limit gives every geom pair a row; on G1 floor work most are pairs out of reach,
        and dropping them made each solve a third faster. The solution is the same."""
        # dt = 1: the velocity is the whole frame step, which the step limit bounds in displacement.
        built = mink.build_ik(self.configuration, tasks, dt=1.0, damping=self.damping, limits=self.limits)
        assert built.G is not None and built.h is not None  # the step limit always bounds the step
        bounded = np.isfinite(built.h)
        inequalities = built.G[bounded]
        bounds = built.h[bounded]
        if self.settings.solver == "daqp":
            return _solve_daqp(built.P, built.q, inequalities, bounds)
        problem = qpsolvers.Problem(built.P, built.q, inequalities, bounds)
        result = qpsolvers.solve_problem(problem, solver=self.settings.solver)
        if not result.found or result.x is None:
            raise mink.NoSolutionFound(self.settings.solver)
        return result.x

    def _clipped(self, q: np.ndarray) -> np.ndarray:
        q = q.copy()
        joints = self.robot.qpos_indices
        q[joints] = np.clip(q[joints], self.step_limit.lower, self.step_limit.upper)
        return q

    def solve(self, frames: Iterable[int]) -> np.ndarray:
        """(T, nq) configurations, frame by frame from the best start (`best_start`); rows of
        frames not visited are NaN."""
        return self._solve_from(self.best_start(), frames)

    def best_start(self) -> np.ndarray:
        """Of the start postures placed at the first frame, the one whose first `start_trial_s`
        solved fit the targets best (lowest mean keypoint error; the first on a tie)."""
        starts = [self.initial_configuration(joints) for joints in self.start_postures]
        if len(starts) == 1:
            return starts[0]
        trial_frames = max(1, round(self.settings.start_trial_s * self.targets.fps))
        trial = range(min(self.targets.n_frames, trial_frames))
        errors = [self._trial_error(start, trial) for start in starts]
        return starts[int(np.argmin(errors))]

    def _trial_error(self, start: np.ndarray, frames: range) -> float:
        """Mean keypoint error of `frames` solved from `start`."""
        solved = self._solve_from(start, frames)[frames.start : frames.stop]
        return float(self.keypoint_errors(solved, frames.start).mean())

    def _solve_from(self, start: np.ndarray, frames: Iterable[int]) -> np.ndarray:
        targets = self.targets
        out = np.full((targets.n_frames, self.robot.model.nq), np.nan)
        self.configuration.update(start)
        previous = None
        window = max(1, round(self.settings.catch_up_window_s * targets.fps))
        recent: deque[float] = deque(maxlen=window)
        for t in frames:
            if previous is None:
                out[t] = self._solve_first_frame(t)
            else:
                # The recent median does not change within a frame.
                lag_limit = np.inf
                if recent:
                    lag_limit = float(np.median(recent)) + self.settings.catch_up_margin_m
                out[t] = self.solve_frame(t, previous, self.root_steps[t], lag_limit)
            recent.append(self._keypoint_error(t))
            previous = out[t]
        return out

    def _solve_first_frame(self, t: int) -> np.ndarray:
        """The first frame places the robot from its start posture: the root may go anywhere, and it
        gets more iterations to converge."""
        self._set_frame_targets(t)
        self.step_limit.start_frame(None, np.full(6, np.inf))
        for _ in range(self.settings.first_frame_iterations):
            self._iterate(self.tasks)
        return self._clipped(self.configuration.q)

    def solve_frame(
        self,
        t: int,
        previous: np.ndarray,
        root_max_step: np.ndarray,
        lag_limit: float,
        extra_tasks: tuple = (),
        catch_up_min_gain_m: float = -np.inf,
    ) -> np.ndarray:
        """Frame `t` warm started from the current configuration, within one frame's step of `previous`.

        A frame whose keypoint error stays above `lag_limit` (a fall, a fast turn) is solved further,
        within the same per-frame bounds, instead of carrying the lag into the next frames; a
        catch-up iteration that lowers the error by less than `catch_up_min_gain_m` is its last.
        """
        tasks = [*self.tasks, *extra_tasks]
        self._set_frame_targets(t)
        self.step_limit.start_frame(previous, root_max_step)
        for _ in range(self.settings.iterations):
            self._iterate(tasks)
        error = self._keypoint_error(t)
        extra = 0
        while extra < self.settings.catch_up_iterations and error > lag_limit:
            self._iterate(tasks)
            extra += 1
            before = error
            error = self._keypoint_error(t)
            if before - error < catch_up_min_gain_m:
                break
        return self._clipped(self.configuration.q)

    def keypoint_errors(self, qpos: np.ndarray, first: int = 0) -> np.ndarray:
        """Mean distance of the key bodies to their targets, per row of `qpos` (frames from `first` on)."""
        errors = np.empty(len(qpos))
        for k, q in enumerate(qpos):
            self.configuration.update(q)
            errors[k] = self._keypoint_error(first + k)
        return errors


def _solve_daqp(P: np.ndarray, q: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray:
    """min 1/2 x'Px + q'x subject to Gx <= h, by DAQP called as qpsolvers calls it, without the
    wrapper's checks and copies (a fifth of each solve's time): the same solution, bit for bit."""
    no_lower_bound = np.full(len(h), -1e30)
    inequality = np.zeros(len(h), dtype=ctypes.c_int)
    x, _, exitflag, _ = daqp.solve(P, q, G, h, no_lower_bound, inequality)
    if exitflag <= 0:
        raise mink.NoSolutionFound("daqp")
    return x


def _frame_step_limit(robot: Robot, fps: float, velocity_margin: float) -> FrameStepLimit:
    """Joint ranges (the config's retarget range), and a step per frame within (a margin of) each
    joint's velocity limit."""
    frame_period = 1.0 / fps
    return FrameStepLimit(
        robot.dof_indices,
        robot.retarget_range[:, 0],
        robot.retarget_range[:, 1],
        robot.qpos_indices,
        robot.model.nv,
        robot.config.velocity_limit * frame_period * velocity_margin,
    )


def _swing_floor_raise(
    targets: RetargetTargets,
    hulls: BodyHulls,
    foot_bodies: tuple[str, str],
    fraction: float,
) -> np.ndarray:
    """(T, bodies of `hulls`) extra floor clearance per frame: a fraction of each foot target's lift.

    A swinging foot keeps part of its target's lift as a hard clearance: skimming the floor
    with a pointed toe reads as dragging, whatever the foot's position error.
    """
    raise_m = np.zeros((targets.n_frames, len(hulls.body_names)))
    feet_columns = [hulls.body_names.index(b) for b in foot_bodies]
    raise_m[:, feet_columns] = fraction * targets.foot_lift
    return raise_m


def _root_step_budget(targets: RetargetTargets, root_body: str, settings: IkConfig) -> np.ndarray:
    """(T, 6) how far the floating base may move in each frame, per tangent axis (world linear,
    body angular): a multiple of its own target's fastest motion nearby plus a minimum, so the root
    can catch up in a fast transition but cannot run off far faster than the human it follows."""
    period = 1.0 / targets.fps
    window = 2 * int(round(settings.root_speed_window_s * targets.fps)) + 1
    position = targets.positions[:, targets.bodies.index(root_body)]
    linear = maximum_filter1d(np.abs(np.diff(position, axis=0, prepend=position[:1])), window, axis=0)
    steps = np.empty((targets.n_frames, 6))
    steps[:, :3] = settings.root_speed_ratio * linear + settings.root_speed_floor_m_s * period
    rotation = targets.orientations.get(root_body)
    if rotation is None:
        steps[:, 3:] = np.inf
        return steps
    relative = np.einsum("tji,tjk->tik", rotation[:-1], rotation[1:])  # previous^T @ next: body frame
    angular = np.abs(Rotation.from_matrix(relative).as_rotvec())
    angular = maximum_filter1d(np.concatenate([angular[:1], angular]), window, axis=0)
    steps[:, 3:] = settings.root_angular_speed_ratio * angular + settings.root_angular_speed_floor_rad_s * period
    return steps
