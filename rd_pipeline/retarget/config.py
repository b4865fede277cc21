"""Retargeting settings: plain frozen dataclasses, importable without the solver stack."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.params import ParamRangeError, require_non_negative, require_positive


@dataclass(frozen=True)
class PlantDrift:
    """A plant ends, and a short swing moves the foot, once both of these have moved since it began."""

    target_m: float = 0.10
    """The foot target of the scaled limb chain, horizontally."""
    human_m: float = 0.05
    """The human foot (scaled like the pelvis), horizontally."""
    swing_s: float = 0.4
    """Length of the swing that moves the foot to its next plant."""


@dataclass(frozen=True)
class TargetShaping:
    """How the human motion is shaped into robot targets."""

    smoothing_s: float = 0.12
    """Gaussian sigma (s) on the human joint paths; mocap jitter would otherwise become joint jerk."""
    swing_clearance_m: float = 0.04
    """Height the lowest point of a swinging foot clears the floor by, once lifted."""
    swing_lift_time_s: float = 0.1
    """Time a swing foot takes to rise to its clearance before it travels (and to come down after)."""
    swing_turn_time_s: float = 0.1
    """Time a foot takes to turn from its flat planted orientation to the human foot's in swing (and back)."""
    reach_fraction: float = 0.97
    """Fraction of the straight-leg length a leg may use; beyond it the body is lowered (`keep_legs_reachable`)."""
    min_stance_fraction: float = 0.6
    """Feet never come sideways closer than this fraction of the robot's rest stance (crossed legs are opened)."""
    leg_correction_smoothing_s: float = 0.1
    """Gaussian sigma (s) of the body lowering and the leg spreading above, so they add no jerk."""
    feet_line_smoothing_s: float = 0.05
    """Gaussian sigma (s) on the direction between the feet that the spreading pushes along."""
    planted_tilt_rad: float = 0.35
    """A planted human foot tilted more than this (kneeling, heel up) takes on the human's tilt, fully at twice it."""
    plant_drift: PlantDrift = PlantDrift()
    """When a long plant is cut by a short swing (a shuffle step the contact label missed)."""
    standing_hips_fraction: float = 0.8
    """The human stands while the hips are higher than this fraction of the leg length (hip to
    knee to ankle). How the human foot lies on its sole is learnt from the plants made standing:
    kneeling, a planted foot may rest on its back, and a clip that opens on the floor would teach
    the robot to lay its sole flat where the human's faces up."""
    upright_shin_fraction: float = 0.7
    """Where a foot is never planted standing, its sole is learnt from the plants whose knee is
    higher above the ankle than this fraction of the shin: a foot under an upright shin lies on
    its sole (a half-kneel's front foot), while kneeling on the toes or the backs of the feet would
    teach it upside down. A foot with neither borrows the other foot's lesson; only where both
    have none is it learnt from every plant."""

    def __post_init__(self) -> None:
        require_positive(self, "swing_clearance_m")
        require_positive(self, "standing_hips_fraction")
        require_positive(self, "upright_shin_fraction")


@dataclass(frozen=True)
class BodyContactConfig:
    """When a human knee, elbow, hand, pelvis or torso rests on the floor (LAFAN1's floor is z = 0)."""

    limb: ContactThresholds = ContactThresholds(
        enter_height_m=0.10,
        enter_speed_m_s=0.3,
        exit_height_m=0.14,
        exit_speed_m_s=0.6,
    )
    """When a limb joint (knee, elbow, wrist) lands on the floor and leaves it (rolling, sliding)."""
    trunk: ContactThresholds = ContactThresholds(
        enter_height_m=0.20,
        enter_speed_m_s=0.3,
        exit_height_m=0.24,
        exit_speed_m_s=0.6,
    )
    """The same for a trunk joint (`trunk_joints`), which sits deeper inside the body."""
    trunk_joints: tuple[str, ...] = ("Hips", "Spine2")
    """LAFAN1 joints that rest on the floor by the `trunk` thresholds."""
    excluded_joints: tuple[str, ...] = ("LeftFoot", "RightFoot", "LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm")
    """Joints never held by this rule: the feet are planted separately; hips and shoulders are rigid on the trunk."""
    release_s: float = 0.3
    """After a contact ends, the held target fades back to the human path over this time."""
    hold_drift_m: float = 0.10
    """A held target is let go for the rest of its contact once the human joint (scaled like the
    targets) has slid this far, horizontally, from where it was when the hold began: the body
    slides on the floor (crawling on the belly, sliding on the back) instead of resting, and
    holding it would tear one body's targets apart (G1 ground2_subject3 164-184 s: a pelvis held
    1.1 m away from its own hips)."""


@dataclass(frozen=True)
class IkWeights:
    """Task costs (position in 1/m, orientation in 1/rad; larger = followed more closely), when a
    swinging foot's cost changes, and the QP's damping."""

    root_position: float = 15.0
    """Pelvis position along its forward and left axes, where they lie level."""
    root_height: float = 50.0
    """Pelvis height: along its own up axis and along the axis of its target that stands upright
    (`tasks._root_costs`). Along its own up axis alone, a performer sitting back or crawling, hips
    tipped 60 degrees, had its height weighed at about half this: H1 kept its pelvis 0.2-0.25 m
    over the scaled hips on the floor cuts of ground2 (ground2_subject2 at 0.8x, 93-113 s: pelvis
    p95 0.256 m; 0.094 held along the vertical too)."""
    root_orientation: float = 5.0
    """Pelvis orientation."""
    torso_orientation: float = 3.0
    """Torso orientation."""
    feet_position: float = 100.0
    """Planted feet position (they must not slide)."""
    swing_feet_position: float = 50.0
    """Swinging feet position, once risen (they guide the leg; the body follows the pelvis). At 20,
    H1's swinging foot trailed its target by 35 mm four frames before touchdown and slid into
    place with its sole already down: on ground2_subject2, 66 % of the left foot's skate and 53 % of
    the right's lay within five frames of a touchdown or liftoff ..."""
    swing_cost_ramp: float = 0.3
    """... eased into over the last this fraction of the foot's rise to the swing clearance; before,
    the planted cost (the target does not travel until it has risen)."""

    feet_orientation: float = 5.0
    """Feet orientation (planted soles flat, or tilted as the human's). Higher keeps soles flatter but
    fights the legs: at 10, on the nine shared takes, feet slide more, joints jerk more and H1's dance
    frames diverge (bench/results/retarget.md at 781a982, against the table before it)."""
    limb_position: float = 0.5
    """Knees, hips, shoulders, elbows and hands."""
    contact_position: float = 20.0
    """A knee, elbow, hand, pelvis or torso while it rests on the floor (held still there)."""
    posture: float = 0.05
    """Pull toward the default pose, for joints the key bodies leave free."""
    damping: float = 0.05
    """Levenberg-Marquardt damping of the QP."""

    def __post_init__(self) -> None:
        require_positive(self, "swing_cost_ramp")


@dataclass(frozen=True)
class IkConfig:
    """How the per-frame solve runs."""

    solve_at_capture_rate: bool = False
    """Solve the capture's own frames (LAFAN1: 30 per second; at most the output rate) and
    resample the solved motion to the output rate, instead of solving every output frame: every
    pass costs per frame solved, so G1 ground2_subject3 retargets in 47 s instead of 75. Off by
    default: with larger steps per frame the solve left G1 dance1_subject1 on a wrong branch of
    the arms for its last 57 s (keypoint error 74 mm instead of 35), which the lag repair did not
    catch."""
    iterations: int = 2
    """Solver iterations per frame (warm started from the previous frame)."""
    first_frame_iterations: int = 50
    """Solver iterations of the first frame, which starts from one of `start_knee_bends`."""
    start_knee_bends: tuple[float, ...] = (0.0, 0.85)
    """Postures the first frame starts from: the default pose with each knee moved this fraction of
    the way to its flexion end (0: the default pose). The IK keeps the branch its first frame lands
    on: G1's cut of ground2_subject3 at 0.8x from 76 s, where the performer kneels and sits back,
    knelt upright from the default pose, its hips thrown back, 0.2 m above the sitting human for
    a second (pelvis p95 0.121 m); started with folded knees it sits on its heels (0.071)."""
    start_trial_s: float = 2.0
    """Seconds solved from each starting posture; the clip starts from the one whose stretch has
    the lowest mean keypoint error (the first on a tie)."""
    solver: str = "daqp"
    """QP solver name (qpsolvers)."""
    velocity_margin: float = 0.95
    """Fraction of each joint's velocity limit a frame step may use."""
    collision_margin_m: float = 0.008
    """Minimum distance kept between configured collision pairs."""
    collision_detection_m: float = 0.05
    """Distance under which a collision pair enters the QP. A pair farther apart bounds a step only
    if the step would close most of that distance at once; from 0.15 m to 0.05 no quality figure of
    the 52-pair retarget bench moved by more than 4 %, and G1 floor work solved 16 % faster, its
    QPs carrying fewer rows, each a distance query and two Jacobians."""
    root_speed_ratio: float = 1.25
    """The pelvis may move per frame, per axis, this many times as far as its target does ..."""
    root_speed_floor_m_s: float = 0.5
    """... plus this speed (m/s), so it can settle where the target stands still."""
    root_angular_speed_ratio: float = 1.5
    """The pelvis may turn per frame, per body axis, this many times as far as its target does ..."""
    root_angular_speed_floor_rad_s: float = 2.0
    """... plus this angular speed (rad/s)."""
    root_speed_window_s: float = 0.15
    """The pelvis target's motion is taken as its fastest within this many seconds either side."""
    catch_up_iterations: int = 8
    """Extra solver iterations a frame may take when it lags its targets ..."""
    catch_up_margin_m: float = 0.03
    """... by this much more than the median keypoint error of the recent frames ..."""
    catch_up_window_s: float = 2.0
    """... over this many seconds."""
    step_halvings: int = 4
    """A step pushing a configured body pair deeper into contact is halved up to this many times, then dropped ..."""
    pair_depth_tolerance_m: float = 0.002
    """... where contact means deeper than this (touching is allowed; the self-collision ruler counts
    from its own `QualityThresholds.self_collision_depth_m`) ..."""
    pair_depth_limit_m: float = 0.004
    """... and the shortest step is still taken while no pair gets deeper than this."""
    floor_clearance_m: float = 0.002
    """Every collision body keeps at least this height above the floor."""
    swing_floor_fraction: float = 0.75
    """A swinging foot's lowest point stays above this fraction of its target's lift (hard)."""
    floor_detection_m: float = 0.05
    """Bodies closer to the floor than this (beyond the clearance) enter the QP."""
    floor_support_reuse: float = 0.05
    """How far a body's up axis (a unit vector, in its own frame) may turn before the floor limit
    scans all its support points again; meanwhile it searches only those that can still be lowest
    (`SupportCandidates`). Speed only: the lowest point found is the same. On G1 floor work the
    floor limit took a fifth of each QP step, most of it scanning the pelvis' and torso's thousands
    of hull points."""
    trajectory_smoothing_s: float = 0.04
    """Gaussian sigma (s) of the sequence-level smoothing of the solved trajectory (0: none)."""
    smoothed_pair_fraction: float = 0.5
    """Where the smoothing brings a collision pair within this fraction of `collision_margin_m` ..."""
    ik_blend_s: float = 0.05
    """... the trajectory eases back to the IK solution, over a Gaussian of this sigma (s)."""
    ground_lift_smoothing_s: float = 0.05
    """Gaussian sigma (s) of the final lift that raises bodies the smoothing dipped below the floor."""
    refine_iterations: int = 1
    """Iterations per frame of the feet refinement after smoothing."""
    refine_correction_rate: float = 10.0
    """How fast (rad/s) the refinement's correction of each joint may change from frame to frame.
    It still binds at stage 30: without it, H1 on ground2_subject3 played at 1.25x, 128-148 s,
    skates 23.1 mm/s instead of 14.2 (the 256 floor cuts otherwise alike)."""
    refine_posture_cost: float = 5.0
    """How strongly the refinement holds joints at their smoothed values (and the pelvis at its
    smoothed position, in 1/m)."""
    pelvis_slack_m: float = 0.03
    """Where the legs alone cannot keep a planted foot on its target (a knee or hip at its range
    limit), how far (m, per axis) the pelvis may move from the smoothed motion to take the
    conflict; the moves are smoothed over `pelvis_slack_smoothing_s` before the legs-only
    refinement. 0 keeps the pelvis where smoothing put it."""
    pelvis_slack_trigger_m: float = 0.005
    """The slack is used only around frames where the legs-only refinement leaves a planted foot
    farther than this from its target: elsewhere the pelvis stays where smoothing put it."""
    pelvis_slack_smoothing_s: float = 0.1
    """Gaussian sigma (s) of the pelvis moves that `pelvis_slack_m` allows."""
    lm_damping: float = 1.0
    """Error-scaled damping of the frame tasks: keeps the solve calm near singular arms and legs."""

    def __post_init__(self) -> None:
        require_positive(self, "start_trial_s")
        if not self.start_knee_bends or not all(0.0 <= bend <= 1.0 for bend in self.start_knee_bends):
            raise ParamRangeError(
                "start_knee_bends", f"must be one or more fractions in [0, 1], got {self.start_knee_bends}"
            )


@dataclass(frozen=True)
class PlantLockConfig:
    """The last pass over planted feet: each plant's foot held over one point by its leg's joints."""

    iterations: int = 6
    """Damped least-squares steps per planted frame at most (0: no lock)."""
    tolerance_m: float = 0.0001
    """A frame whose planted feet are all this close to their points takes no more steps."""
    damping: float = 1e-6
    """Damping (m^2) of each step: keeps a leg near straight from flailing for the last millimetre."""
    reach_m: float = 0.04
    """A held foot never moves more than this from where the earlier passes put it: past that, it
    slides along with them (pulling a dragged foot all the way back flips the leg). 0.02 until
    stage 33: over the 256 floor cuts 0.04 brings the mean skate 2.66 -> 2.43 mm/s and the worst
    15.1 -> 14.1 (H1-2's crawl on ground2_subject3 x0.8 205-225 s, where the legs drag the feet
    50-120 mm off their plants). The pelvis reads higher on nine cuts, by up to 0.026 m (H1-2
    fallAndGetUp3_subject1 x0.8 101-121 s, 0.073 -> 0.099); stage 25 had not kept it because it
    moves the wider-ranges copy the bench excuses pelvis frames with (the floor-work study)."""
    slip_m: float = 0.002
    """A held foot the leg leaves farther than this (horizontally) from its point is held from
    where it is."""
    release_s: float = 0.1
    """After a foot lifts, seconds over which the hold eases off."""
    max_step_rad: float = 0.2
    """Largest change of any leg joint in one step."""
    pelvis_give_m: float = 0.01
    """Where a leg cannot hold its planted foot (a joint at its stop), how far (m, each horizontal
    axis) the pelvis may move from the earlier passes' to hold it (0: the legs alone). H1's ankle
    has one joint and stops the leg on floor work; the whole robot moves instead."""
    pelvis_give_smoothing_s: float = 0.04
    """Gaussian sigma (s) of the pelvis's gives: smoothed into one motion of the pelvis, under
    which the legs hold the feet again, so the pelvis does not shake frame by frame."""
    step_halvings: int = 2
    """A step that takes the feet farther from their points is halved up to this many times."""

    def __post_init__(self) -> None:
        require_positive(
            self, "tolerance_m", "damping", "reach_m", "slip_m", "release_s", "max_step_rad", "pelvis_give_smoothing_s"
        )
        require_non_negative(self, "pelvis_give_m")


@dataclass(frozen=True)
class MovingFootClearance:
    """The last pass over swinging feet: a foot that travels is off the floor.

    The robot's foot trails a fast swing target (by up to 12 cm on quick floor steps), so it
    comes down to the floor while it still travels to where it will be held, and leaves the floor
    after it has started to travel: for those frames it is dragged over the floor.
    """

    clearance_m: float = 0.03
    """A foot that is not planted and travels is lifted by its leg until its lowest point is at
    least this high (0: no pass)."""
    speed_m_s: float = 0.05
    """A foot travels while its horizontal speed is above this."""
    detour_m: float = 0.001
    """A lift that turns the foot so that its horizontal path through the frame grows by more
    than this is not taken: the foot would travel more, not less."""
    turn_weight_m: float = 0.05
    """How much the foot keeps its orientation while it rises (m of position per radian): a
    foot lifted by its position alone pitches toe-down and its sole rises less than its body."""
    land_from_above: bool = True
    """A foot that still travels on the first frame of its plant is lifted there too: it comes
    down on its plant from above on the next frame instead of sliding into it. Its landing frame
    had been the last step of its swing taken 1 cm over the floor (on H1's 0.8x crawl, 27 % of
    the skate)."""
    passes: int = 3
    """Passes over the take: a lift that moves a foot sideways makes its neighbouring frames
    travel, and the next pass lifts those."""

    def __post_init__(self) -> None:
        require_positive(self, "speed_m_s", "detour_m", "passes")
        require_non_negative(self, "clearance_m", "turn_weight_m")


@dataclass(frozen=True)
class LagRepair:
    """When and how a stretch of frames that fell far behind its targets is solved again.

    A forward solve can stay on a branch the human has left (bent over while the human already
    sits); solved backward from where it has caught up again, the same stretch often is not. The
    stretch is solved forward once more, guided towards whichever solution is closer to the targets
    frame by frame, within the same per-frame limits, once per guide cost; the best of those is
    kept only if it lags less.
    """

    error_ratio: float = 2.0
    """A frame lags when its keypoint error is this many times the take's median (0: no repair) ..."""
    error_margin_m: float = 0.1
    """... and at least this much above it."""
    padding_s: float = 1.0
    """Seconds re-solved before and after a lagging stretch (overlapping windows merge)."""
    guide_costs: tuple[float, ...] = (1.0, 4.0)
    """Posture costs pulling the re-solve towards the frame's better solution: the stretch is
    re-solved at each, and the one with the lowest mean keypoint error over the stretch is kept.
    No one cost suited every stretch at stage 24: at 1, H1 ground2_subject2 75-95 s slid back onto
    the lying branch while the performer sat up (pelvis p95 0.285 m; 0.146 at 4); at 4, G1
    ground2_subject2 61-70 s followed the backward solve frame by frame onto a worse stretch
    (0.080 -> 0.130). Since the pelvis is held to its height along the vertical (stage 30), the two
    costs read alike on the first (100 diverged frames at 4, 105 at 1) and the second needs no
    repair. Cost 1 alone over the 256 floor cuts at stage 30: one more cut meets every bar (an
    excused pelvis 0.101 -> 0.100) and the keypoint error rises, 78.6 -> 79.7 mm; not taken."""
    rejoin_s: float = 0.5
    """After the stretch, seconds over which the re-solve is guided back to and cross-faded into the
    first solution, so the splice is continuous."""
    catch_up_min_gain_m: float = 0.0005
    """In the re-solve, a catch-up iteration that lowers the frame's mean keypoint error by less
    than this is the frame's last. Its frames lag by construction, and on floor work most lag
    because the ranges cannot reach the pose: there all 8 catch-up iterations ran for a median
    gain of 0.01 mm. The forward solve keeps every catch-up iteration: cut there, they moved a
    getting-up take onto a worse branch."""

    def __post_init__(self) -> None:
        if not self.guide_costs or min(self.guide_costs) <= 0:
            raise ParamRangeError("guide_costs", f"must be one or more positive costs, got {self.guide_costs}")


@dataclass(frozen=True)
class PelvisRepair:
    """When a stretch near the floor where the pelvis stayed above its target is solved again
    with the pelvis held harder, and when that is kept (`pelvis_repair.py`).

    Held harder over whole clips, the pelvis came down wherever it sat too high, but the feet
    slid on the cuts where the body lies and gets up again (the floor-work study, "Tried with
    stage 30"): H1's pelvis sat on its hip housings, 0.12 m over the scaled hips, on
    fallAndGetUp2_subject3 24-44 s (pelvis p95 0.107 m)."""

    gains: tuple[float, ...] = (5.0, 3.0, 2.0)
    """The pelvis's position costs are multiplied by each of these in turn in the re-solve,
    stiffest first; the first re-solve the judge keeps is kept (empty: no repair). One gain did
    not suit every stretch at stage 31: at 5, H1 ground2_subject3 mirrored 61-81 s slid its
    finished feet 4.2 -> 78.8 mm/s and was refused (excused pelvis 0.101 m), where 3 lowers the
    pelvis 0.117 -> 0.070 m over its target with the feet at 4.5; H1-2 ground2_subject2 x0.8
    93-113 s was refused at 5 (15.6 -> 46.6) and kept at 3 (12.0; pelvis p95 0.149 -> 0.089)."""
    hips_below_m: float = 0.20
    """A frame is raised while the scaled human hips are lower than this (lying, sitting) ..."""
    raised_m: float = 0.06
    """... and the pelvis is more than this above its target."""
    visible_m: float = 0.08
    """... and a padded stretch is solved again only if somewhere in it the pelvis is more than
    this higher over the scaled hips than its median over the clip: the deviation the quality
    ruler reads, whose bar is 0.10 m. Below it a re-solve changes no verdict, and with its judge
    it costs about as much as the whole clip's IK (G1 ground2_subject3 164-184 s: 3.5 -> 7.0 s)."""
    padding_s: float = 0.5
    """Seconds re-solved before and after a raised stretch (overlapping stretches merge)."""
    rejoin_s: float = 0.5
    """After the stretch, seconds over which the re-solve is cross-faded into the first solve."""
    judge_margin_s: float = 1.0
    """Seconds on each side of a window that are finished (smoothed, feet refined, plants locked)
    with it to judge it: the feet of the IK's own output slide 40-180 mm/s on floor work before
    those passes, and no reading taken there told a re-solve they mend from one they do not."""
    skate_tolerance_m_s: float = 0.002
    """A re-solve is kept only if it lowers the finished pelvis and its finished feet slide on
    the floor at most this much faster, on the mean, than the first solve's."""

    def __post_init__(self) -> None:
        if any(gain <= 1.0 for gain in self.gains):
            raise ParamRangeError("gains", f"must each be above 1, got {self.gains}")
        require_positive(self, "hips_below_m", "raised_m")
        require_non_negative(self, "visible_m", "padding_s", "rejoin_s", "judge_margin_s", "skate_tolerance_m_s")


@dataclass(frozen=True)
class RetargetConfig:
    """Output rate and the settings of each retargeting step (`--set retarget.weights.feet_position=50`)."""

    fps: float = 50.0
    """Frame rate of the reference motion."""
    contact: ContactThresholds = ContactThresholds(ground_percentile=2.0)
    """When a human foot counts as planted; each ankle and toe's planted height is its own
    `ground_percentile` height over the clip."""
    shape: TargetShaping = TargetShaping()
    """How the human motion becomes robot targets."""
    body_contact: BodyContactConfig = BodyContactConfig()
    """When knees, elbows, hands, pelvis and torso rest on the floor."""
    weights: IkWeights = IkWeights()
    """IK task costs."""
    ik: IkConfig = IkConfig()
    """IK iterations, limits and the sequence-level smoothing."""
    repair: LagRepair = LagRepair()
    """When stretches that fell far behind their targets are solved again."""
    pelvis_repair: PelvisRepair = PelvisRepair()
    """When a pelvis left above its target near the floor is solved again."""
    plant_lock: PlantLockConfig = PlantLockConfig()
    """How planted feet are held still in the end."""
    moving_feet: MovingFootClearance = MovingFootClearance()
    """How feet that travel between plants are kept off the floor."""

    def __post_init__(self) -> None:
        require_positive(self, "fps")
