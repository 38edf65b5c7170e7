"""The identification loop (identification paper, Fig. 3): perceive every frame, plan when the goal is
reached, drive, and keep the head on the object.

One control step (period ``dt``, the same on the simulator and on the real robot)::

    frame    = robot.capture_stereo()                         # images, G_RC and odometry at capture
    bank.predict(...)                                         # Eq. (1)-(2) for every model
    roi      = the box at every predicted pose, or None       # full frame when lost or too large
    D_k      = stereo_features(frame, roi)                    # 3D SIFT features
    bank.update_all(matches of D_k against each B_i)          # EKF per model, batched
    belief   = calcCurrentEntropy(...)                        # Eq. (7)-(9), (5)
    head     : tracking (Eq. (16)-(17)) or scanning           # HeadController
    base     : follow the arc to the goal; HALT while scanning after a lost track
    at goal  : plan = calcPossibleControlActions + calcExpectedEntropy, u* by Eq. (6)
               (or the best goal ahead, if nearly as good: see below)

The robot drives on arcs of the ring around the probability-weighted object estimate, so the path to a
goal never crosses the object. It stops when one model's probability stays above ``stop_probability``
for ``dwell_s`` seconds, or when the action or time budget is spent.

**Keeping the direction of travel.** The gain of Eq. (4) is computed for the object as it stands at the
decision; the paper's operator then turns the unique face away while the robot drives (4-7 s a goal).
Against that, only travel that keeps one way round the ring gains on the face: it closes the angle at
the robot's angular speed (15-17 deg/s) minus the box's turn rate (8.6 deg/s), and each reversal gives
the gained angle back. So once the robot has driven one way, the best goal ahead that way is taken when
its gain is at least ``keep_direction`` (0.5) of the best
(:func:`~lab.identification.planner.continue_direction`), and a goal across the ring is reached going
the same way. The operator's lag puts the face ahead of a robot that keeps going, so a belief that puts
it behind is usually a coin flip between two hidden faces. With the plain argmax (1.0) the robot can
bounce across the box between two beliefs; 0.5 identified every evasive episode it was measured on,
with fewer actions than 0.7 or 1.0. How it was chosen: docs/tuning/keep-direction.md.

**The box's look-alike turns.** Three faces carry the same page, so RANSAC can seat a model's filter
on any quarter-turn of the box (measured: 3 of 4 filters start 90 degrees off). Each frame is scored
at the filters' poses *and* their quarter-turns (:func:`calc_current_entropy` with ``symmetries``);
every ``keyframe_s`` the frame is scored at each filter's turns (:class:`TurnEvidence`), a filter
whose own turn the keyframes support clearly less than another is re-seated on it, and the planner
weighs each model's four turns by that evidence (:meth:`ModelHypotheses.from_estimates`). When a model
is identified, its filter is seated on the turn at which the frame that favoured it most was scored
(the view of its unique face), so that the final pose is not a turn off.

**Fallbacks.** No filter took in a frame for ``lost_after_s``: the track is lost, the head scans and
the base halts; once a filter takes one in again, the interrupted goal is resumed (or replanned if the
object moved). No ring goal reachable on the floor plan (:class:`RingBlocked`): hold position, keep
observing, plan again after ``retry_s``.

The agent uses only the :class:`lab.robot.Robot` interface: it runs unchanged on :class:`lab.sim.SimRobot`
and on :class:`lab.hardware.HardwareRobot`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from lab.errors import ConfigError
from lab.estimation import (
    CalibrationUncertainty,
    EKFBank,
    EKFConfig,
    ModelUncertainty,
    OrientationChart,
    UpdateOutcome,
)
from lab.geometry import G_to_pose6, Pose2D, wrap_angle
from lab.identification.actions import ActionConfig, RingBlocked
from lab.identification.bayes import uniform
from lab.identification.final_pose import ConsistentShadows
from lab.identification.head import HeadController, HeadMode
from lab.identification.hypotheses import (
    ModelHypotheses,
    NoObjectEstimate,
    TurnEvidence,
    symmetry_log_weights,
    turn_between,
    z_turns,
)
from lab.identification.loop_config import AgentConfig, DecisionRecord, PlannerChoice, StepRecord
from lab.identification.planner import continue_direction, plan_next_best_view, ring_smoothed
from lab.identification.scoring import ModelScorer, ScoringConfig
from lab.identification.step import observe_frame
from lab.navigation.follower import PathFollower
from lab.robot import Robot, frame_motion
from lab.vision import FeatureDatabase, JointIndex, Matcher, StereoParams, stereo_features
from lab.vision.roi import RegionOfInterest, tracked_roi

__all__ = ["PlannerChoice", "AgentConfig", "StepRecord", "DecisionRecord", "IdentificationAgent"]


_ACROSS_RING = math.radians(150.0)  # a goal this far round the ring is reached the way the robot was going


class IdentificationAgent:
    """The closed loop of the identification paper on any :class:`Robot`.

    The agent is handed everything it uses; its constructor renders nothing, trains nothing and reads
    no cache (a run loads the databases and tables: :mod:`lab.runs.identify`).

    Parameters
    ----------
    robot : Robot
        Every camera-derived quantity (projection, field of view, the clutter density of Eq. (9))
        comes from ``robot.camera``.
    databases : sequence of FeatureDatabase
        The models ``B_i``, in the order of the probabilities (their ``name`` names the models).
    evaluator : optional
        The expected-entropy evaluator of the ``lut`` or ``mc`` planner
        (:func:`~lab.identification.evaluators.make_evaluator`); required by those two, unused by the
        baselines.
    config : AgentConfig, optional
    planner : PlannerChoice or str
    seed : int
        Seeds RANSAC and the random planner.
    scoring : ScoringConfig, optional
        How frames are scored; its clutter density, when unset, from ``robot.camera``.
    action_config : ActionConfig, optional
    observer : callable, optional
        ``observer(agent, frame)`` after every step (live views, recordings: :mod:`lab.viz.live`);
        kept as :attr:`on_step`. None (the default) costs nothing.
    floor_plan : lab.navigation.CostGrid, optional
        A known map (obstacles grown by the robot's radius): only ring goals that A* reaches on it
        from the robot's odometry pose are candidates (:func:`~lab.identification.actions.reachable_on`).
        Without it every goal of the ring is a candidate.

    Raises
    ------
    ConfigError
        An unknown planner, no databases, or the ``lut`` / ``mc`` planner without an evaluator.
    """

    def __init__(
        self,
        robot: Robot,
        databases: Sequence[FeatureDatabase],
        evaluator=None,
        config: AgentConfig | None = None,
        planner="lut",
        seed: int = 0,
        scoring: ScoringConfig | None = None,
        action_config: ActionConfig | None = None,
        observer=None,
        floor_plan=None,
    ):
        self._check_inputs(planner, databases, evaluator)
        self.robot = robot
        self.names = tuple(db.name for db in self.dbs)
        self.config = config or AgentConfig()
        self.scoring = (scoring or ScoringConfig()).for_camera(robot.camera)  # clutter density: this camera's
        self.action_config = action_config or ActionConfig()
        self.rng = np.random.default_rng(seed)
        self._build_models(seed)
        self.head = HeadController(robot.camera, robot.pan_tilt_limits)
        self.follower = PathFollower(
            robot.base_limits,
            goal_tolerance_xy=self.config.arrive_xy * 0.6,
            goal_tolerance_theta=math.radians(self.config.arrive_theta_deg * 0.6),
        )
        self.evaluator = evaluator
        self._start_loop_state(observer, floor_plan)

    def _check_inputs(self, planner, databases, evaluator) -> None:
        """Set :attr:`planner` and :attr:`dbs`, or a ConfigError: an unknown planner, no databases, or
        the ``lut`` / ``mc`` planner without an evaluator."""
        try:
            self.planner = PlannerChoice(planner) if isinstance(planner, str) else planner
        except ValueError:
            raise ConfigError(
                f"unknown planner {planner!r}; planners: {', '.join(p.value for p in PlannerChoice)}"
            ) from None
        self.dbs = list(databases)
        if not self.dbs or not all(isinstance(db, FeatureDatabase) for db in self.dbs):
            raise ConfigError(
                "IdentificationAgent needs a sequence of FeatureDatabase (one per model), got "
                f"{type(databases).__name__} {databases!r:.60}"
            )
        if evaluator is None and self.planner in (PlannerChoice.LUT, PlannerChoice.MC):
            raise ConfigError(
                f"the {self.planner.value} planner needs an expected-entropy evaluator: build it with "
                "lab.identification.make_evaluator (lab.runs.identify.build_agent does it all)"
            )

    def _build_models(self, seed: int) -> None:
        """The models' scoring (a joint index of the databases, one scorer and one matcher each) and their
        EKF bank (seeded with ``seed``)."""
        robot = self.robot
        # one exact search of every model's database a frame (the shared faces' features stored once)
        self.index = JointIndex(self.dbs, self.scoring.k_neighbours)
        self.scorers = [ModelScorer(db, self.scoring, self.index, i) for i, db in enumerate(self.dbs)]
        # the EKF's correspondences from the scorers' exact search, made once per frame and model
        # (observe_frame): exact, and faster than a FLANN search of a few hundred features
        self.matchers = [
            Matcher(db, method="brute", k=s.k_neighbours)
            for db, s in zip(self.dbs, self.scorers, strict=True)
        ]
        self.bank = EKFBank(
            len(self.dbs),
            EKFConfig(
                chart=OrientationChart.ROTATION_VECTOR,
                calibration=CalibrationUncertainty.of_camera(robot.camera),  # shared by a frame's features
                model=ModelUncertainty(max(db.point_std_m for db in self.dbs)),  # by all frames
            ),
            rng=np.random.default_rng(seed),
        )
        self.final_pose = ConsistentShadows(self.bank)  # the pose the run states (final_pose.py)

    def _start_loop_state(self, observer, floor_plan) -> None:
        """The loop's state before the first step: a uniform belief, no records, no goal, no track."""
        self.P = uniform(len(self.dbs))
        self.steps: list[StepRecord] = []
        self.decisions: list[DecisionRecord] = []
        self._prev = None
        self._goal: Pose2D | None = None
        self._ring_index = 0
        self._above_since: float | None = None
        self._tracking_since: float | None = None
        self._arrival_t: float | None = None
        self.identified: int | None = None
        self.on_step = observer  # optional callable(agent, frame) for live views
        self.last_features = self.last_observation = None  # the last frame's D_k and its FrameObservation
        self.floor_plan = floor_plan
        self.n_blocked = 0  # decisions that found every ring goal blocked (held position, retried)
        self.n_lost = 0  # times the track was lost (scan, halt, then resume or replan)
        self._retry_at: float | None = None
        self._last_seen_t: float | None = None  # last frame a filter took in
        self._lost = False
        self.turns = z_turns(self.config.symmetry_turns)
        self.turn_evidence = TurnEvidence(len(self.dbs), len(self.turns), self.config.keyframes)
        self._last_keyframe_t: float | None = None
        self.n_reseats = 0  # filters moved to a better-supported turn
        # per model: (log-likelihood lead, turn of its filter) of the frame that favoured it most
        self._decisive: list[tuple[float, int] | None] = [None] * len(self.dbs)
        self._direction = 0  # the last drive's direction round the ring (+1 ccw, -1 cw, 0 none yet)
        self.stereo = StereoParams(sharpen=False)  # the box is near: sharpening gained nothing
        self._extent = np.max([np.asarray(db.extent, dtype=float) for db in self.dbs], axis=0)
        self.last_roi: RegionOfInterest | None = None  # the last frame's region (None: the full frame)

    # --- where to look ----------------------------------------------------------------------------
    def region_of_interest(self, predicted, camera) -> RegionOfInterest | None:
        """The region of the left image to extract while tracking: the box (the largest database
        extent) at every filter's predicted pose and each of its look-alike turns, each corner widened
        by ``roi_n_sigma`` standard deviations of its pixel position (:func:`~lab.vision.roi.tracked_roi`).

        None (the full frame) with ``roi`` off, when the track is lost, no filter has a pose, or the
        region would cover more than ``roi_max_fraction`` of the image."""
        cfg = self.config
        if not cfg.roi or self._lost:
            return None
        poses = [(e.G_CO @ T, e.Sigma_rv) for e in predicted if e is not None for T in self.turns]
        if not poses:
            return None
        return tracked_roi(
            poses,
            self._extent,
            camera,
            self.stereo.min_disparity,
            self.stereo.max_disparity,
            margin_px=cfg.roi_margin_px,
            n_sigma=cfg.roi_n_sigma,
            max_fraction=cfg.roi_max_fraction,
        )

    # --- one step ---------------------------------------------------------------------------------
    def _perceive(self, frame):
        """Predict every model's filter to this frame, then update filters and probabilities with it."""
        if self._prev is not None:
            motion = (self._prev.G_RC, frame.G_RC, frame_motion(self._prev, frame), frame.t - self._prev.t)
            self.final_pose.predict(*motion)  # first: it compares the filters with their last update
            self.bank.predict(*motion)
        self._prev = frame
        predicted = self.bank.estimates
        self.last_roi = roi = self.region_of_interest(predicted, frame.camera)
        f = stereo_features(frame.left, frame.right, frame.camera, self.stereo, roi=roi, t=frame.t)
        obs = observe_frame(
            self.P, f, self.bank, predicted, self.matchers, self.scorers, self.scoring, self.turns
        )
        self.P = obs.belief.P
        self.last_features, self.last_observation = f, obs
        self.final_pose.update(obs.updates, obs.matches)
        if any(u.outcome is not UpdateOutcome.SKIPPED for u in obs.updates):
            self._last_seen_t = frame.t
        self._follow_reinitialised_filters(predicted, obs.updates)
        self._keyframe(frame, f)
        self._note_decisive_turn(obs.belief)
        return f, obs

    # --- the box's look-alike turns ----------------------------------------------------------------
    def _follow_reinitialised_filters(self, predicted, updates) -> None:
        """A filter that RANSAC re-initialised on another copy of the shared page turned by a quarter:
        re-index its turn evidence (or forget it when the new pose is unrelated to the old)."""
        for i, (before, u) in enumerate(zip(predicted, updates, strict=True)):
            if u.outcome not in (UpdateOutcome.INITIALIZED, UpdateOutcome.REINITIALIZED):
                continue
            after = self.bank[i].estimate
            k = None if before is None or after is None else turn_between(before.G_CO, after.G_CO, self.turns)
            self._decisive[i] = None  # its turns are now relative to another pose
            if k is None:
                self.turn_evidence.forget(i)
            elif k:
                self.turn_evidence.reseated(i, k)

    def _keyframe(self, frame, features) -> None:
        """Every ``keyframe_s``, score the frame at each filter's look-alike turns and re-seat a filter
        whose own turn the keyframes support clearly less than another (the shared faces let RANSAC
        lock on any of them; only the unique face, or its absence where a turn puts it, tells)."""
        cfg = self.config
        if len(self.turns) < 2 or len(features) == 0:
            return
        if self._last_keyframe_t is not None and frame.t - self._last_keyframe_t < cfg.keyframe_s - 1e-9:
            return
        est = self.bank.estimates
        if all(e is None for e in est):
            return
        self._last_keyframe_t = frame.t
        G_WC = frame.odom.G() @ frame.G_RC
        lw = symmetry_log_weights([(features, G_WC)], self.scorers, est, G_WC, self.turns, self.scoring)
        self.turn_evidence.add(lw)
        total = self.turn_evidence.total()
        for i, e in enumerate(est):
            k = int(np.argmax(total[i]))
            if e is None or k == 0 or total[i, k] - total[i, 0] < cfg.reseat_margin:
                continue
            self.bank[i].initialize(G_to_pose6(e.G_CO @ self.turns[k]), None, Sigma_rv=e.Sigma_rv)
            self.turn_evidence.reseated(i, k)
            self._decisive[i] = None
            self.n_reseats += 1

    def _note_decisive_turn(self, belief) -> None:
        """Remember, for each model, the look-alike turn of its filter at which the frame that favoured
        it most over the others was scored (``Belief.pose``, under the common pose)."""
        pose = belief.pose
        if pose is None or len(self.turns) < 2:
            return
        ll = np.asarray(belief.log_likelihoods, dtype=float)
        for i, e in enumerate(self.bank.estimates):
            if e is None or len(ll) < 2:
                continue
            gap = float(ll[i] - np.delete(ll, i).max())
            best = self._decisive[i]
            if gap > 0 and (best is None or gap > best[0]):
                k = turn_between(e.G_CO, pose.G_CO, self.turns)
                if k is not None:
                    self._decisive[i] = (gap, k)

    def _seat_identified(self, i: int) -> None:
        """Seat the identified model's filter on the turn its most decisive frame was scored at.

        The probabilities score every model at the best of the filters' poses and their look-alike
        turns, so a model can be identified from its unique face while its own filter still sits a turn
        off (180 degrees off in evasive episodes, where the turn evidence, one keyframe a second, had not
        yet passed ``reseat_margin``). The frame that favoured the model most is the one that saw the
        unique face; the turn it was scored at is where the unique face is. What it was measured on:
        docs/tuning/identified-model-reseat.md.
        """
        rec = self._decisive[i]
        est = self.bank[i].estimate
        if rec is None or rec[1] == 0 or est is None:
            return
        k = rec[1]
        self.bank[i].initialize(G_to_pose6(est.G_CO @ self.turns[k]), None, Sigma_rv=est.Sigma_rv)
        self.turn_evidence.reseated(i, k)
        self._decisive[i] = None
        self.n_reseats += 1

    def _object_origin_C(self) -> np.ndarray | None:
        """The probability-weighted origin of the tracked models, in the current camera frame."""
        est = self.bank.estimates
        known = [i for i, e in enumerate(est) if e is not None]
        if not known:
            return None
        w = np.array([self.P[i] for i in known])
        w = w / w.sum()
        return np.sum([wk * est[i].mu[:3] for wk, i in zip(w, known, strict=True)], axis=0)

    def _hypotheses(self, frame) -> ModelHypotheses:
        """Each model's pose and its look-alike turns, weighted by the keyframes' turn evidence."""
        G_WC = frame.odom.G() @ frame.G_RC
        return ModelHypotheses.from_estimates(
            self.P, self.bank.estimates, G_WC, self.turns, self.turn_evidence.total()
        )

    def _arc_path(self, centre_xy, goal: Pose2D, pose: Pose2D, direction: int = 0) -> np.ndarray:
        """Waypoints along the ring from the robot's angle to the goal's: the short way round, or in
        ``direction`` (+1 counter-clockwise, -1 clockwise) when the goal is across the ring."""
        cx, cy = centre_xy
        r = math.hypot(goal.x - cx, goal.y - cy)
        a0 = math.atan2(pose.y - cy, pose.x - cx)
        a1 = math.atan2(goal.y - cy, goal.x - cx)
        da = wrap_angle(a1 - a0)
        if direction and da * direction < 0 and abs(da) > _ACROSS_RING:
            da += direction * 2 * math.pi  # across the ring: keep going the way the robot was going
        n = max(2, int(abs(da) / math.radians(10)) + 1)
        a = a0 + np.linspace(0.0, da, n)
        pts = np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)
        pts[0] = (pose.x, pose.y)
        pts[-1] = (goal.x, goal.y)
        return pts

    def _decide(self, frame) -> bool:
        """Choose the next goal (Eq. (6), or the best goal ahead when it is nearly as good: see
        ``keep_direction``); False when no decision is possible (no estimate, ring blocked)."""
        try:
            hyp = self._hypotheses(frame)
        except NoObjectEstimate:
            return False
        centre = hyp.object_centre_W()
        t0 = time.perf_counter()
        here = math.atan2(frame.odom.y - centre[1], frame.odom.x - centre[0])
        kept = False
        reachable = None
        if self.floor_plan is not None:
            from lab.identification.actions import reachable_on

            reachable = reachable_on(self.floor_plan, frame.odom)
        try:
            if self.planner in (PlannerChoice.LUT, PlannerChoice.MC):
                plan = plan_next_best_view(
                    hyp, self.robot.camera, self.evaluator, self.action_config, reachable
                )
                actions, gains, best = plan.actions, np.asarray(plan.gain), plan.best
                if self._direction and self.config.keep_direction < 1:
                    k = continue_direction(
                        gains,
                        actions,
                        here,
                        self._direction,
                        self.config.keep_direction,
                        tie_break=ring_smoothed(gains, actions),
                    )
                    kept = k is not None and k != best
                    best = best if k is None else k
            else:
                from lab.identification.actions import calc_possible_control_actions

                actions = calc_possible_control_actions(
                    centre, self.robot.camera, self.action_config, reachable
                )
                gains = np.full(len(actions), np.nan)
                if self.planner is PlannerChoice.RANDOM:
                    best = int(self.rng.integers(len(actions)))
                else:
                    want = here + math.radians(self.config.circle_step_deg)
                    best = int(np.argmin([abs(wrap_angle(a.azimuth - want)) for a in actions]))
        except RingBlocked:  # hold position, keep observing, and plan again after retry_s
            self.n_blocked += 1
            self._retry_at = frame.t + self.config.retry_s
            return False
        goal = actions[best].pose
        self._goal = goal
        da = wrap_angle(actions[best].azimuth - here)
        if kept or abs(da) > _ACROSS_RING:
            direction = self._direction or (1 if da >= 0 else -1)  # ahead, or across the ring
        elif abs(da) < 0.5 * math.radians(self.action_config.step_deg):
            direction = 0  # stays put: the direction of travel is kept for the next decision
        else:
            direction = 1 if da > 0 else -1
        self._direction = direction or self._direction
        path = self._arc_path(centre[:2], goal, frame.odom, self._direction)
        self.follower.set_path(path, final_heading=goal.theta)
        cands = np.array([[a.pose.x, a.pose.y, a.pose.theta] for a in actions])
        self.decisions.append(
            DecisionRecord(
                frame.t,
                self.planner.value,
                cands,
                gains,
                best,
                np.asarray(centre),
                time.perf_counter() - t0,
                direction,
                kept,
            )
        )
        return True

    def step(self) -> StepRecord:
        """One control step (see the module docstring)."""
        cfg = self.config
        robot = self.robot
        frame = robot.capture_stereo()
        f, _ = self._perceive(frame)
        self._check_track(frame)
        cmd = self.head.command(robot.pan_tilt(), None if self._lost else self._object_origin_C(), cfg.dt)
        robot.command_pan_tilt(cmd.pan, cmd.tilt)
        tracking = cmd.mode is HeadMode.TRACKING
        if tracking:
            self._tracking_since = frame.t if self._tracking_since is None else self._tracking_since
        else:
            self._tracking_since = None
        arrived = self._arrived(frame.odom)
        if arrived and self._goal is not None and self._arrival_t is None:
            self._arrival_t = frame.t
        action = None
        settled = tracking and frame.t - self._tracking_since >= cfg.settle_s
        retry_ok = self._retry_at is None or frame.t >= self._retry_at
        if (
            settled
            and arrived
            and retry_ok
            and len(self.decisions) < cfg.max_actions
            and self.identified is None
        ):
            if self._decide(frame):  # the gain is computed when the goal is reached (the paper's Fig. 3)
                action = len(self.decisions) - 1
                self._arrival_t = None
        if not tracking:
            robot.drive(0.0, 0.0)  # HALT until the track is re-established
            base_mode = "halted"
        elif not self._arrived(frame.odom):
            c = self.follower.command(frame.odom, frame.t)
            robot.drive(c.v, c.omega)
            base_mode = "driving"
        else:
            robot.drive(0.0, 0.0)
            base_mode = "idle"
        est_W = np.full((len(self.dbs), 4, 4), np.nan)
        G_WC = frame.odom.G() @ frame.G_RC
        for i, e in enumerate(self.bank.estimates):
            if e is not None:
                est_W[i] = G_WC @ e.G_CO
        odom = (frame.odom.x, frame.odom.y, frame.odom.theta)
        rec = StepRecord(frame.t, self.P.copy(), cmd.mode.value, base_mode, odom, len(f), action, est_W)
        self.steps.append(rec)
        if self.on_step is not None:
            self.on_step(self, frame)
        if float(self.P.max()) >= cfg.stop_probability:
            self._above_since = frame.t if self._above_since is None else self._above_since
            if frame.t - self._above_since >= cfg.dwell_s:
                self.identified = int(np.argmax(self.P))
                self._seat_identified(self.identified)
        else:
            self._above_since = None
        robot.step(cfg.dt)
        return rec

    def _check_track(self, frame) -> None:
        """Lose the track when no filter has taken in a frame for ``lost_after_s``; on re-acquiring it,
        resume the interrupted goal, or replan if the object's estimate moved (the paper's Sec. IV)."""
        cfg = self.config
        seen = self._last_seen_t
        if not self._lost:
            if seen is not None and frame.t - seen > cfg.lost_after_s:
                self._lost = True
                self.n_lost += 1
            return
        if seen is None or frame.t - seen > 1e-9:  # still nothing taken in this frame
            return
        self._lost = False
        if self._goal is not None and self.decisions:
            try:
                centre = self._hypotheses(frame).object_centre_W()
            except NoObjectEstimate:
                return
            if np.linalg.norm(centre[:2] - self.decisions[-1].centre_W[:2]) > cfg.replan_shift_m:
                self._goal = None  # arrived by definition: the next settled step plans again
                self._arrival_t = None

    def _arrived(self, pose: Pose2D) -> bool:
        """At the current goal (or there is none), within the arrival tolerances."""
        g = self._goal
        if g is None:
            return True
        return math.hypot(pose.x - g.x, pose.y - g.y) <= self.config.arrive_xy and abs(
            wrap_angle(pose.theta - g.theta)
        ) <= math.radians(self.config.arrive_theta_deg)

    def run(self) -> int | None:
        """Step until identified or a budget is spent; returns the identified model's index or None.

        With the action budget spent, the robot observes from its last goal for ``final_observe_s``.
        """
        cfg = self.config
        t_end = self.robot.now() + cfg.max_time_s
        if not self.robot.enabled:
            self.robot.enable()
        try:
            while self.identified is None and self.robot.now() < t_end:
                spent = len(self.decisions) >= cfg.max_actions
                if (
                    spent
                    and self._arrival_t is not None
                    and self.robot.now() - self._arrival_t > cfg.final_observe_s
                ):
                    break
                self.step()
        finally:
            self.robot.stop()
        return self.identified

    @property
    def n_actions(self) -> int:
        return len(self.decisions)
