"""Notebook 04: the real robot.

``make_notebooks.py`` writes these cells as ``04_real_robot.ipynb``: ``INTRO``, then its common set-up
cell, then ``CELLS``.
"""

INTRO = [
    (
        "md",
        r"""# 04 The real robot

Everything so far ran on `SimRobot`. The physical robot is an **iRobot Create 2** base, a **Directed
Perception PTU-D46** pan-tilt unit and a USB **stereo camera**. `HardwareRobot` drives them through the
same `lab.robot.Robot` interface: the same methods, units (metres, radians, seconds), frames and
exceptions. So every algorithm of notebooks 00-03 runs on it unchanged, and this notebook runs the same
cells on both robots, side by side: move the head, drive, read the odometry, the watchdog, the
emergency stop, a safety stop, and a stereo frame.

**No robot attached** (the default, and in CI): the notebook starts **emulators**, small programs that
speak the PTU's ASCII protocol and the Create's binary Open Interface on pseudo-terminals. The real
drivers talk to them over real serial I/O, with the real timing: on hardware, `robot.step(dt)` *waits*
`dt` seconds, where the simulator computes them.

**With the robot:** go through the bring-up checklist in `hardware/README.md` first. Then set the
environment variable `LAB_ROBOT_CONFIG=hardware/robot.toml` before starting Jupyter. Put the robot on
the floor with 2 m of free space around it, and keep a hand near the Create's power button.""",
    ),
    (
        "md",
        r"""**Learning objectives.** After this notebook you can:

1. run the same code on the simulator and on the hardware adapter through the one `Robot` interface;
2. turn a base command $(v, \omega)$ into the wheel speeds of a differential drive, and the wheels' travel into odometry;
3. predict how far the base goes under its acceleration limit, and explain the watchdog, the emergency stop and a safety stop;
4. rehearse the object search on the device emulators before the real robot runs it.

**Prerequisites:** notebooks [00](00_simulator_and_stereo.ipynb)-[03](03_grid_search.ipynb); planar kinematics (a pose $(x, y, \theta)$, a rotation by $\theta$). For the real robot: the bring-up checklist in `hardware/README.md`.

**Time:** about 60 minutes on the emulators (reading 25, exercises 35); plus a robot session of 60-90 minutes. The exercises marked *checked* answer back when you run their cell: "correct", or a hint
that names your mistake (`lab.exercises`); until you write your code they say "not attempted yet". This
notebook prepares the [`search` assignment](../assignments/search/README.md); the course plan is
[docs/course.md](../docs/course.md).""",
    ),
]

SUMMARY = [
    (
        "md",
        r"""## Summary

* `SimRobot` and `HardwareRobot` share one interface (metres, radians, seconds; the same exceptions), so every algorithm runs on both unchanged.
* A differential drive turns $(v, \omega)$ into wheel speeds $v \mp \omega\, b / 2$; its odometry integrates the wheels' travel and drifts.
* A drive command holds for 0.5 s (the watchdog); the emergency stop latches; a safety stop (a lifted robot, a cliff) stops the base until it is enabled again.
* A rehearsal runs the real drivers on emulators with a rendered camera: the object search runs there before it runs in the room.

**Next:** [05 Localization against the room](05_localization.ipynb). **Assignment:** [`search`](../assignments/search/README.md) (its
README says what to write and how it is graded).""",
    ),
]

CELLS = [
    (
        "md",
        r"""## Connect

A TOML file describes the robot: serial ports, speed limits, the PTU's directions and zero offsets, the
camera and its calibration file. Without a robot we use `hardware/rehearsal.toml`, a **rehearsal**: the
same robot on the emulators, with a camera that renders the simulator's world (the arena, box `M1` on
its carrier 1.2 m ahead) from the emulators' *true* state: where the Create emulator has driven, where
the PTU emulator points the head. Everything else, the drivers, the odometry from the wheel encoders,
the rectification, is the real robot's code. The simulated robot beside it stands in the same scene.""",
    ),
    (
        "code",
        """\
import contextlib
import dataclasses
from pathlib import Path
from lab.geometry import Pose2D
from lab.hardware import HardwareRobot, load_config
from lab.runs.rehearsal import rehearsal
from lab.sim import SimRobot, SimWorld, load_box_models

REPO = Path.cwd().parent                          # the notebooks run in notebooks/
CONFIG = os.environ.get("LAB_ROBOT_CONFIG")       # e.g. hardware/robot.toml; unset: a rehearsal
EMULATED = CONFIG is None
stack = contextlib.ExitStack()                    # closes what we open, in the last cell

world = stack.enter_context(SimWorld("arena"))    # the simulated robot's scene: as the rehearsal's
world.add_carrier(load_box_models()[1], Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi)   # M1, unique face to -x
sim = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=0)
stack.callback(sim.close)

if EMULATED:
    cfg = load_config(REPO / "hardware" / "rehearsal.toml")
    # The emulators are threads of this kernel. On a busy machine they can miss the Create's 15 ms sensor
    # stream for longer than the real robot's 0.1 s, and the adapter rightly stops as if the cable were cut
    # (DeviceTimeout). A rehearsal allows them 0.5 s.
    cfg = dataclasses.replace(cfg, base=dataclasses.replace(cfg.base, stale_timeout_s=0.5))
    r = stack.enter_context(rehearsal(cfg, true_model=1, box_yaw=math.pi))
    hw, emulators = r.robot, r.emulators          # a HardwareRobot on the PTU and Create 2 emulators
    print("emulators on", emulators.ports)
else:
    emulators = None
    hw = stack.enter_context(HardwareRobot(Path(CONFIG) if Path(CONFIG).is_absolute() else REPO / CONFIG))
robots = {"simulator": sim, "hardware": hw}
print(f"hardware robot: {hw.state}; PTU limits read from the unit: {hw.pan_tilt_limits}")
# the rehearsal carries the simulator's calibration (it states a real calibration's accuracy, the ideal
# simulator none: StereoCamera.depth_scale_std, pointing_std_deg, focal_std)
same = dataclasses.replace(hw.camera, depth_scale_std=0.0, pointing_std_deg=0.0, focal_std=0.0) == sim.camera
assert same or not EMULATED
""",
    ),
    (
        "md",
        r"""## The same cells on both robots

Two small functions that know only the `Robot` interface. Motion commands need `enable()` first (they
raise `NotEnabled` otherwise), and a drive command holds only until the next one: a control loop
re-sends it every period.""",
    ),
    (
        "code",
        """\
def look(robot, pan, tilt):
    \"\"\"Turn the head to (pan, tilt) [rad] and wait until it is there.\"\"\"
    robot.command_pan_tilt(pan, tilt)
    return robot.wait_pan_tilt()

def drive_for(robot, v, omega, duration, resend=True, dt=0.1):
    \"\"\"Drive at (v [m/s], omega [rad/s]) for duration [s]; re-send every dt, or (resend=False) only once.
    Returns the odometry trace: rows (t [s], x [m], y [m], theta [rad]), time from the start.\"\"\"
    t0, trace = robot.now(), []
    robot.drive(v, omega)
    while robot.now() - t0 < duration - 1e-9:
        robot.step(dt)
        if resend:
            robot.drive(v, omega)
        p = robot.odometry()
        trace.append((robot.now() - t0, p.x, p.y, p.theta))
    return np.array(trace)

moved = {}
for name, robot in robots.items():
    robot.enable()
    s = look(robot, 0.3, -0.1)
    p0 = robot.odometry()
    trace = drive_for(robot, 0.2, 0.0, 1.0)
    robot.stop()
    p1 = robot.odometry()
    moved[name] = math.hypot(p1.x - p0.x, p1.y - p0.y)
    print(f"{name:9s}: head at pan {s.pan:+.4f}, tilt {s.tilt:+.4f} rad; drove {moved[name]:.3f} m in "
          f"{trace[-1, 0]:.2f} s; odometry {p1}")
    assert abs(s.pan - 0.3) < 0.002 and abs(s.tilt + 0.1) < 0.002
# 0.4 s of ramp at 0.5 m/s^2, then 0.2 m/s: 0.16 m in 1 s on both
assert all(0.12 < d < 0.2 for d in moved.values()) and abs(moved["simulator"] - moved["hardware"]) < 0.03
""",
    ),
    (
        "md",
        r"""**Exercise 1 (checked): wheel speeds.** The Create 2 takes one speed per wheel (Drive Direct, in mm/s); the `Robot` interface takes the base's forward speed $v$ [m/s] and turn rate $\omega$ [rad/s], counter-clockwise positive. Write `my_wheel_speeds(v, omega, track)` returning `(v_left, v_right)` in m/s, `track` the distance between the wheels [m]. The check drives your wheel speeds forward and compares the base's motion with the command.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_wheel_speeds

def my_wheel_speeds(v, omega, track):
    raise NotImplementedError   # your code: (v_left, v_right) [m/s]

check_wheel_speeds(my_wheel_speeds)
""",
    ),
    (
        "md",
        r"""**Exercise 2 (checked): the ramp.** The comment above says 0.16 m in 1 s at 0.2 m/s: the base speeds up at its acceleration limit. Write `my_ramp_distance(v, accel, duration)`: the distance [m] a base at rest covers in `duration` [s] when commanded to `v` [m/s] with the acceleration limit `accel` [m/s^2] (it may not reach `v` at all). The check integrates the speed numerically.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_ramp_distance

def my_ramp_distance(v, accel, duration):
    raise NotImplementedError   # your code: a distance [m]

check_ramp_distance(my_ramp_distance)
""",
    ),
    (
        "md",
        r"""## The watchdog

A drive command holds for `cmd_timeout_s` (0.5 s). If no new one comes (a program that hangs, a cell
that raised, a lost network link), the base stops by itself. Here each robot gets *one* command and
then only waits. Watch the two curves after the timeout: the simulator slows down within its
deceleration limit, while the hardware adapter sends the Create a zero speed at once (a stop, not a
manoeuvre). The `Robot` contract allows both; what it requires is that the base stops.""",
    ),
    (
        "code",
        """\
traces = {}
for name, robot in robots.items():
    if EMULATED and name == "hardware":
        t_cmd = emulators.create.now()            # the emulator's own clock
    traces[name] = drive_for(robot, 0.2, 0.0, 1.6, resend=False)
    tr = traces[name]
    late = tr[tr[:, 0] >= 1.1]                    # well after the timeout and the slewed stop
    assert np.ptp(late[:, 1]) < 0.003, f"{name} kept driving"
    plt.plot(tr[:, 0], tr[:, 1] - tr[0, 1], ".-", label=name)
plt.axvline(hw.cmd_timeout_s, color="k", ls=":", label="cmd_timeout_s")
plt.xlabel("time since the one drive command [s]"); plt.ylabel("x - x(0) [m]"); plt.legend()
print(f"watchdog stops so far: {hw.watchdog_stops}; last event: {hw.events[-1].message}")
assert hw.watchdog_stops >= 1
if EMULATED:                                      # what reached the wheels: the emulator's log
    zero = emulators.create.first_zero_drive_after(t_cmd)
    print(f"the Create received a zero Drive Direct {zero.t - t_cmd:.2f} s after the command")
""",
    ),
    (
        "md",
        r"""**Exercise 3 (checked): one odometry step.** The odometry the robots report adds up the wheels' travel. Write `my_odometry_step(pose, d_left, d_right, track)`: the new pose $(x, y, \theta)$ [m, m, rad] after the wheels rolled `d_left`, `d_right` [m] (a few centimetres). The check compares with a fine numerical integration of the arc; a first-order step is accurate enough.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_odometry_step

def my_odometry_step(pose, d_left, d_right, track):
    x, y, theta = pose
    raise NotImplementedError   # your code: return (x, y, theta) after the step

check_odometry_step(my_odometry_step)
""",
    ),
    (
        "md",
        r"""## Emergency stop and safety stops

`estop()` stops everything and **latches**: every motion command raises `EStopActive` until
`clear_estop()`, and then `NotEnabled` until `enable()`. A **safety stop** comes from the robot itself:
the Create's Safe mode stops the wheels when it is lifted (wheel drop) or sees a cliff; the adapter
then raises `SafetyStop` from the next command or step, and never re-arms on its own. We lift the
emulated robot (the simulator has a cliff switch for the same purpose); on the real robot, lift it
yourself to try it.""",
    ),
    (
        "code",
        """\
from lab.errors import EStopActive, NotEnabled, SafetyStop

def expect(error, call):
    try:
        call()
    except error as e:
        return f"{type(e).__name__}: {e}"
    raise AssertionError(f"{error.__name__} was not raised")

lift = {"simulator": lambda: sim.trip_safety("cliff")}
if EMULATED:
    lift["hardware"] = lambda: emulators.create.wheel_drop(True)

for name, robot in robots.items():
    robot.drive(0.1, 0.0)
    robot.estop()
    print(f"{name}: after estop:        {expect(EStopActive, lambda: robot.drive(0.1, 0.0))}")
    robot.clear_estop()
    print(f"{name}: after clear_estop:  {expect(NotEnabled, lambda: robot.drive(0.1, 0.0))}")
    robot.enable()
    if name in lift:
        robot.drive(0.1, 0.0)
        lift[name]()
        msg = expect(SafetyStop, lambda: [robot.step(0.02) for _ in range(150)])   # raised within 3 s
        print(f"{name}: lifted:             {msg}")
        assert not robot.enabled
        if name == "hardware":
            emulators.create.wheel_drop(False)    # back on the floor
        robot.enable()
    robot.stop()
""",
    ),
    (
        "md",
        r"""## A stereo frame

`capture_stereo()` returns the rectified pair with the head's state and the odometry at capture, on
both robots. The stereo features of notebook 00 and the matching against a box database of notebook
01 run on it unchanged.""",
    ),
    (
        "code",
        """\
from lab.vision import Matcher, stereo_features
from lab.training import get_database

db = get_database("M1")
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
counts = {}
for a, (name, robot) in zip(ax, robots.items()):
    look(robot, 0.0, math.atan2(0.49 - 0.7, 1.1))     # at the box: its centre 0.49 m high, the head 0.7 m
    frame = robot.capture_stereo(after=robot.now())
    f = stereo_features(frame.left, frame.right, frame.camera)
    m = Matcher(db).match(f)
    counts[name] = (len(f), len(m.pairs(f, db)[0]))
    a.imshow(frame.left); a.axis("off")
    a.plot(f.uv[:, 0], f.uv[:, 1], "y.", ms=3)
    a.set_title(f"{name}: {counts[name][0]} features, {counts[name][1]} matched to M1")
print(counts)
if EMULATED:   # the rendered pair went through the hardware's rectification and the same pipeline
    assert all(n_matched >= 10 for _, n_matched in counts.values())
""",
    ),
    (
        "code",
        """\
print(hw.read_state().counters)                  # what the drivers counted: frames, commands, retries ...
stack.close()                                     # the robots, the emulators and the worlds
""",
    ),
    (
        "md",
        r"""## The object search on the robot

The search agent of notebook 03 also knows only the `Robot` interface, so `run_search` runs it on a robot
as well: `robot_config=` is the one switch. In a rehearsal the lab room (`worlds/lab_room.toml`) is
rendered from the emulators' state, the object placed where `place` says (or by the seed), as in the
simulator. On the real robot, stand it at the room's start (the scene's `[robot] start`: its odometry
starts there) and put the object where you like; there is no truth then, so the scoring fields
(`true_pose`, the errors, `success`) are `None`, unless you measure the object's pose and give it as
`truth=(x, y, z, yaw_deg)`. The robot's clock is the wall clock: the time budget is real seconds; when it
is used up the base is stopped and the result says so. **Ctrl-C** ("interrupt kernel") stops the motors
and returns what was found so far, with the reason `"interrupted"`. The command line does the same:
`lab search --robot hardware/rehearsal.toml --object cereal_box --seed 3 --json r.json`.

In fast mode the box stands 0.8 m in front of the robot and the colour scan and the navigator's first
look take one view each (the same agent, fewer views).""",
    ),
    (
        "code",
        """\
from lab.navigation.navigator import NavigatorConfig
from lab.runs.search import navigator_factory, run_search
from lab.search import SearchAgentConfig
from lab.search.global_search import GlobalSearchConfig

config, navigate = None, navigator_factory        # the agent's and the navigator's defaults
place = (0.0, -1.6, 0.0, -90.0)                   # the cereal box 1.4 m in front of the robot's start
if FAST:
    config = SearchAgentConfig(global_search=GlobalSearchConfig(pans_deg=(0.0,), tilts_deg=(-30.0,)))
    navigate = lambda robot, spec: navigator_factory(robot, spec, config=NavigatorConfig(scan_pans=(0.0,)))
    place = (0.0, -2.2, 0.0, -90.0)
if EMULATED:
    robot_config = REPO / "hardware" / "rehearsal.toml"
else:                                             # the real robot: the object is where you put it
    robot_config, place = (Path(CONFIG) if Path(CONFIG).is_absolute() else REPO / CONFIG), None
res = run_search("cereal_box", seed=0, place=place, max_time=120.0, navigate=navigate, config=config,
                 robot_config=robot_config)
d = res.to_json()                                 # what `lab search --json` writes
for e in d["events"]:
    print(f"{e['t']:6.1f} s  {e['kind']:8s} {e['detail']}")
print({k: d[k] for k in ("found", "success", "reason", "position_error_m", "orientation_error_deg",
                         "path_length_m", "sim_time_s", "watchdog_stops")})
if EMULATED:   # scored against the rendered world: the box where `place` put it
    assert d["found"] and d["success"] and d["position_error_m"] < 0.05
""",
    ),
    (
        "md",
        r"""## Exercise

1. Call `drive_for(hw, 0.2, 0.0, 2.0, dt=0.6)`: the command is re-sent every 0.6 s, just longer than the
   watchdog's 0.5 s. Plot the odometry: what do you see, and what would a real robot do?
2. With the emulators, make the pan-tilt unit stall (`emulators.ptu.stall = True`) and call `look(hw, 0.5, 0.0)`.
   What is raised, and after how long? Where is that time set?
3. The identification agent of notebook 02 uses only the `Robot` interface, so it runs on `hw` unchanged:
   `lab identify --robot hardware/rehearsal.toml --true-model 2 --mover static --max-actions 2` runs it in a
   rehearsal. Compare its control steps with the simulator's: here `step(dt)` waits `dt` *after* the
   computation. What does that do to the watchdog (`hw.watchdog_stops`)?
4. Run the search with `max_time=10.0`: how does it end, and where is the base? Then run it again and
   interrupt the kernel while the robot drives: what does `res.reason` say, and what did the emulated
   Create's wheels receive (`emulators.create.drives()` of a rehearsal you open yourself)?""",
    ),
]
