"""A localization drive: the robot drives a seeded loop through the lab room and localizes on the way.

The run the localization benchmark (``benchmarks/bench_localization.py``) repeats and the closed-loop
test shortens. The robot follows corners of a seeded rectangle on its *estimated* pose (a turn in place
towards the next corner, then a straight drive with a proportional heading correction), keeps its head
on the landmark it sees best and takes a frame every ``frame_every_m`` of travel; at each corner it
re-localizes actively (:meth:`LocalizedRobot.relocalize`). The truth is read only to score: the final
position error of the odometry and of the estimate, and the NEES of the estimate at each update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lab.geometry import wrap_angle
from lab.localization import LocalizationMode, LocalizedRobot, LocalizerConfig
from lab.runs.room import sim_localizer_told, surveyed_map
from lab.training.landmarks import trained_landmark_map

__all__ = ["DriveResult", "drive_loop_waypoints", "run_localization_drive"]


@dataclass(frozen=True)
class DriveResult:
    """Outcome of one localization drive (errors against the simulator's truth, for scoring only).

    Attributes
    ----------
    seed : int
    mode : str
    path_length_m : float
        Distance driven (true).
    odometry_error_m, odometry_heading_error_deg : float
        Final error of the wheel odometry.
    localization_error_m, localization_heading_error_deg : float
        Final error of the estimate.
    nees : ndarray, shape (k,)
        ``e^T Sigma^-1 e`` of the estimate after each accepted landmark update (e against the truth).
    n_updates, n_rejected : int
    trajectory : ndarray, shape (n, 10)
        ``t``, true ``x, y, theta``, odometry ``x, y, theta``, estimate ``x, y, theta``.
    ellipses : list of (x (3,), Sigma (3, 3))
        The estimate and covariance at each corner, for figures.
    sigma_xy_m : float
        The estimate's final position standard deviation (larger ellipse axis).
    """

    seed: int
    mode: str
    path_length_m: float
    odometry_error_m: float
    odometry_heading_error_deg: float
    localization_error_m: float
    localization_heading_error_deg: float
    nees: np.ndarray = field(repr=False)
    n_updates: int = 0
    n_rejected: int = 0
    trajectory: np.ndarray = field(default=None, repr=False)
    ellipses: list = field(default_factory=list, repr=False)
    sigma_xy_m: float = 0.0


def drive_loop_waypoints(rng: np.random.Generator, length_m: float) -> np.ndarray:
    """Corners (k, 2) [m] of a seeded rectangle through the lab room's free floor, repeated to about
    ``length_m`` of path (direction and start corner seeded, each corner jittered by up to 0.25 m)."""
    base = np.array([[-1.5, -2.0], [1.8, -2.0], [1.8, 0.4], [-1.5, 0.4]])
    if rng.random() < 0.5:
        base = base[::-1]
    base = np.roll(base, int(rng.integers(4)), axis=0)
    pts, total, prev = [], 0.0, np.array([0.0, -3.0])
    while total < length_m:
        for c in base:
            p = c + rng.uniform(-0.25, 0.25, 2)
            total += float(np.hypot(*(p - prev)))
            pts.append(p)
            prev = p
            if total >= length_m:
                break
    return np.array(pts)


def _best_landmark_head(robot: LocalizedRobot, x) -> tuple[float, float] | None:
    """Pan and tilt towards the landmark best seen from ``x`` (largest apparent facing width)."""
    obs = robot.observer
    lim = robot.pan_tilt_limits
    best = None
    for lm in obs.map:
        r, bearing = obs.map.bearing_in_robot(lm, x)
        facing = lm.facing(x[:2])
        if r > robot.config.max_range_m or facing < robot.config.min_facing:
            continue
        pan = wrap_angle(bearing)
        if not lim.pan_min + 0.05 <= pan <= lim.pan_max - 0.05:
            continue
        score = facing * lm.width_m / max(r, 0.6)
        tilt = math.atan2(lm.centre_W[2] - robot.camera.mount_R[2], r)
        tilt = float(np.clip(tilt, lim.tilt_min + 0.02, lim.tilt_max - 0.02))
        if best is None or score > best[0]:
            best = (score, pan, tilt)
    return None if best is None else best[1:]


def run_localization_drive(
    seed: int,
    mode: str = "landmarks",
    length_m: float = 30.0,
    sensing="realistic",
    config: LocalizerConfig | None = None,
    frame_every_m: float = 0.5,
    speed: float = 0.3,
    supersample: int = 1,
    world: str = "lab_room",
) -> DriveResult:
    """Drive about ``length_m`` around the seeded loop in the simulator and score the localization.

    ``config`` None: the localizer as a search's (:func:`lab.runs.room.sim_localizer_told`: under the
    room's mount errors it estimates the camera's yaw on the base); a config given is used as it is."""
    from lab.runs.robots import make_robot
    from lab.scene import load_scene
    from lab.sim import RenderSettings, SimWorld

    mode = LocalizationMode.parse(mode)
    rng = np.random.default_rng([seed, 20])
    corners = drive_loop_waypoints(rng, length_m)
    scene = load_scene(world)
    landmarks = trained_landmark_map(scene, progress=False) if mode is LocalizationMode.LANDMARKS else None
    with (
        SimWorld(scene, RenderSettings(supersample=supersample)) as w,
        make_robot(world=w, seed=seed, sensing=sensing) as run,
    ):
        base = run.robot
        base.enable()
        if landmarks is not None and not base.sensing.room.is_none:  # the room's errors: a surveyed map
            landmarks = surveyed_map(landmarks, base.sensing, seed)
        told = sim_localizer_told(base)  # the stated start sigma, camera latency and camera yaw's state
        told_config = told.pop("config", None)
        config = config if config is not None else told_config  # the caller's config wins
        robot = LocalizedRobot(
            base, mode, landmarks, config, rng=np.random.default_rng([seed, 21]), log=lambda m: None, **told
        )
        drive = _LoopDrive(w, base, robot, mode)
        drive.record()
        for goal in corners:
            drive.turn_towards(goal)
            drive.drive_to(goal, speed, frame_every_m)
            drive.relocalize_at_corner()
        truth = w.truth.robot_pose()
        odom = base.odometry()
        est = robot.pose_estimate()
        hist = robot.localizer.history
    return DriveResult(
        seed=int(seed),
        mode=mode.value,
        path_length_m=drive.travelled,
        odometry_error_m=math.hypot(odom.x - truth.x, odom.y - truth.y),
        odometry_heading_error_deg=abs(math.degrees(wrap_angle(odom.theta - truth.theta))),
        localization_error_m=math.hypot(est.pose.x - truth.x, est.pose.y - truth.y),
        localization_heading_error_deg=abs(math.degrees(wrap_angle(est.pose.theta - truth.theta))),
        nees=np.array(drive.nees),
        n_updates=sum(r.accepted for r in hist),
        n_rejected=sum(not r.accepted for r in hist),
        trajectory=np.array(drive.rows),
        ellipses=drive.ellipses,
        sigma_xy_m=est.sigma_xy_m,
    )


class _LoopDrive:
    """One localization drive under way: the robot, the simulator's truth it is scored against (and only
    scored), the distance travelled and what was recorded (trajectory rows, corner ellipses, NEES)."""

    dt = 0.05  # [s] per control step

    def __init__(self, w, base, robot: LocalizedRobot, mode: LocalizationMode):
        self.w, self.base, self.robot, self.mode = w, base, robot, mode
        self.rows, self.ellipses, self.nees = [], [], []
        self.travelled = 0.0
        self.last_truth = w.truth.robot_pose()
        self.next_frame = 0.0

    def record(self) -> None:
        """One trajectory row: the time, the true pose, the odometry and the estimate."""
        t = self.w.truth.robot_pose()
        o = self.base.odometry()
        e = self.robot.odometry()
        self.rows.append((self.robot.now(), t.x, t.y, t.theta, o.x, o.y, o.theta, e.x, e.y, e.theta))

    def _score_updates(self, n0: int) -> None:
        """The NEES of each update accepted since the localizer's ``n0``-th, against the true pose now."""
        t = self.w.truth.robot_pose().as_array()
        for rec in self.robot.localizer.history[n0:]:
            if rec.accepted:
                err = rec.x - t
                err[2] = wrap_angle(err[2])
                self.nees.append(float(err @ np.linalg.solve(rec.Sigma, err)))

    def look(self) -> None:
        n0 = len(self.robot.localizer.history)
        self.robot.capture_stereo()
        self._score_updates(n0)

    def point_head(self, x) -> None:
        if self.mode is LocalizationMode.LANDMARKS:
            head = _best_landmark_head(self.robot, x)
            if head is not None:
                self.robot.command_pan_tilt(*head)

    def advance(self) -> None:
        self.robot.step(self.dt)
        t = self.w.truth.robot_pose()
        self.travelled += math.hypot(t.x - self.last_truth.x, t.y - self.last_truth.y)
        self.last_truth = t

    def turn_towards(self, goal) -> None:
        """Turn in place towards the corner ``goal``."""
        robot = self.robot
        for _ in range(400):
            p = robot.odometry()
            err = wrap_angle(math.atan2(goal[1] - p.y, goal[0] - p.x) - p.theta)
            if abs(err) < math.radians(2.0):
                break
            robot.drive(0.0, float(np.clip(2.0 * err, -1.0, 1.0)))
            self.advance()

    def drive_to(self, goal, speed: float, frame_every_m: float) -> None:
        """Drive to ``goal``, correcting the heading, with the head on the best landmark."""
        robot = self.robot
        for _ in range(4000):
            p = robot.odometry()
            dx, dy = goal[0] - p.x, goal[1] - p.y
            dist = math.hypot(dx, dy)
            if dist < 0.05:
                break
            err = wrap_angle(math.atan2(dy, dx) - p.theta)
            v = speed * max(0.0, math.cos(err)) * min(1.0, dist / 0.3 + 0.2)
            robot.drive(v, float(np.clip(2.0 * err, -1.0, 1.0)))
            self.advance()
            if self.mode is LocalizationMode.LANDMARKS and self.travelled >= self.next_frame:
                self.point_head(robot.localizer.x)
                self.look()
                self.next_frame = self.travelled + frame_every_m
            if len(self.rows) == 0 or robot.now() - self.rows[-1][0] >= 0.5:
                self.record()

    def relocalize_at_corner(self) -> None:
        """Stop, re-localize actively (landmarks mode), keep the estimate's ellipse and record a row."""
        robot = self.robot
        robot.stop()
        for _ in range(4):
            self.advance()
        if self.mode is LocalizationMode.LANDMARKS:
            n0 = len(robot.localizer.history)
            robot.relocalize()
            self._score_updates(n0)
        est = robot.pose_estimate()
        self.ellipses.append((est.pose.as_array(), est.Sigma))
        self.record()
