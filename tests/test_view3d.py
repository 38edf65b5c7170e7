"""The recorded 3D view (lab.viz.view3d): its scene against the run's own records and the simulator's
truth, read back from the saved file itself (the HTML page's embedded viser recording, decoded here
independently of the recorder), and the page is self-contained."""

from __future__ import annotations

import base64
import re
import subprocess
import sys

import numpy as np
import pytest

viser = pytest.importorskip("viser", reason="the optional extra view3d (viser) is not installed")
from lab.viz.view3d_page import LAST_STEP_HOLD_S  # noqa: E402

zstandard = pytest.importorskip("zstandard")
msgspec = pytest.importorskip("msgspec")


def recording(html: str) -> tuple[float, list[tuple[float, dict]]]:
    """The page's embedded recording: its duration [s] and its timed messages, binary arrays decoded
    (viser's format: 8-byte size + zstd( 8-byte msgpack length + msgpack + 8-aligned buffers ))."""
    b64 = re.search(r'__VISER_EMBED_DATA__="([^"]+)"', html).group(1)
    raw = base64.b64decode(b64)
    size = int.from_bytes(raw[:8], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[8:], max_output_size=size)
    n = int.from_bytes(inner[:8], "little")
    payload = msgspec.msgpack.decode(inner[8 : 8 + n])
    buffers, off = [], 8 + n
    for length in payload["binaryBufferLengths"]:
        off += (8 - off % 8) % 8
        buffers.append(inner[off : off + length])
        off += length

    def resolve(v):
        if isinstance(v, dict) and "__binary_index" in v and "dtype" in v:
            return np.frombuffer(buffers[v["__binary_index"]], dtype=np.dtype(v["dtype"]))
        if isinstance(v, dict):
            return {k: resolve(x) for k, x in v.items()}
        if isinstance(v, list):
            return [resolve(x) for x in v]
        return v

    return payload["durationSeconds"], [(t, resolve(m)) for t, m in payload["messages"]]


def last_position(messages, name: str) -> np.ndarray:
    pos = [m["position"] for _, m in messages if m.get("name") == name and m["type"] == "SetPositionMessage"]
    return np.asarray(pos[-1], float)


@pytest.fixture(scope="module")
def identify_run(tmp_path_factory):
    """One short identification episode recorded in 3D, with the truth and the agent's state at every
    step kept beside it (for the test only)."""
    from lab.runs.identify import run_identify
    from lab.viz.live.identification import identification_inliers

    out = tmp_path_factory.mktemp("view3d")
    seen = {"robot": [], "ellipsoids": [], "features": []}

    def attach(agent, carrier):
        viewer = agent.on_step  # the 3D view, hooked by the run
        seen["viewer"] = viewer

        def observer(a, frame):
            viewer(a, frame)
            seen["shapes"] = {s.name: s.G_W.copy() for s in carrier.world.truth.shapes()}
            seen["robot"].append(seen["shapes"]["robot"])
            G_WC = frame.odom.G() @ frame.G_RC
            ell = {}
            for i, e in enumerate(a.bank.estimates):
                if e is not None:
                    R = G_WC[:3, :3]
                    ell[a.names[i]] = (a.steps[-1].estimates_W[i][:3, 3].copy(), R @ e.Sigma[:3, :3] @ R.T)
            seen["ellipsoids"].append(ell)
            known = [i for i, e in enumerate(a.bank.estimates) if e is not None]
            top = max(known, key=lambda k: float(a.P[k])) if known else None
            counts = (0, 0) if top is None else tuple(len(u) for u in identification_inliers(a, top))
            n = 0 if a.last_features is None else len(a.last_features)
            seen["features"].append((n, *counts))

        agent.on_step = observer

    res = run_identify(
        2, seed=3, mover="static", planner="circle", max_actions=1, max_time_s=3.0, figures=False,
        view3d=out / "identify.html", attach=attach,
    )  # fmt: skip
    return res, seen, (out / "identify.html").read_text()


def test_identify_view_has_one_step_per_frame_and_the_files_poses_are_the_worlds(identify_run):
    res, seen, html = identify_run
    viewer = seen["viewer"]
    n = len(res["history"])
    assert n >= 5
    assert len(viewer.steps) == n + 1  # the world at the start, then one step per stereo frame
    assert res["view3d"].endswith("identify.html")
    duration, messages = recording(html)
    t = [s.t for s in viewer.steps]
    # the time slider spans the episode, and holds its last step (the player never shows its very end)
    assert duration == pytest.approx(t[-1] - t[0] + LAST_STEP_HOLD_S, abs=1e-6)
    frustums = [m for _, m in messages if m["type"] == "CameraFrustumMessage"]
    assert len(frustums) == n  # one camera per frame
    # every body at the last step, as written into the file, is where the simulator had it (the robot
    # and the carrier moved; a table's legs are bodies of their own, posed in W)
    from lab.viz.view3d import body_node_name

    assert len(seen["shapes"]) >= 5 and "robot" in seen["shapes"]
    for body, G_W in seen["shapes"].items():
        assert np.allclose(last_position(messages, body_node_name(body)), G_W[:3, 3], atol=1e-4), body
    # and is posed in W: no body's node is a child of another node (a child's pose is its parent's
    # frame's in the viewer)
    names = {m.get("name") for _, m in messages if m.get("name")}
    for body in seen["shapes"]:
        node = body_node_name(body)
        assert not any(node.startswith(other + "/") for other in names - {"/world"}), node


def test_identify_chart_ends_at_the_final_probabilities_and_entropy(identify_run):
    from scipy.stats import entropy

    res, seen, _ = identify_run
    viewer = seen["viewer"]
    series = [n for st in viewer.steps for k, n in st.nodes.items() if k.startswith("/chart/series/")]
    assert len(series) == len(res["history"]) - 1  # one segment per frame after the first
    P = np.asarray(res["final_posterior"], float)
    z = series[-1].props["segments"][:, 1, 2] - viewer._chart_origin[1][2]
    assert np.allclose(z[:-1], P) and z[-1] == pytest.approx(entropy(P) / np.log(len(P)))


def test_identify_ellipsoids_are_three_sigma_of_each_models_covariance(identify_run):
    _, seen, html = identify_run
    _, messages = recording(html)
    last = seen["ellipsoids"][-1]
    assert last, "no model had a pose estimate in the episode"
    for name, (centre, Sigma_W) in last.items():
        mesh = [
            m for _, m in messages if m["type"] == "MeshMessage" and m["name"] == f"/models/{name}/ellipsoid"
        ]
        v = np.asarray(mesh[-1]["props"]["vertices"], np.float32).reshape(-1, 3).astype(float) - centre
        w = np.linalg.eigvalsh(Sigma_W)
        # every vertex on the 3-sigma surface, and the longest semi-axis 3 sqrt(largest eigenvalue)
        d2 = np.einsum("ij,jk,ik->i", v, np.linalg.inv(Sigma_W), v)
        assert np.allclose(np.sqrt(d2), 3.0, rtol=2e-3)
        assert np.linalg.norm(v, axis=1).max() == pytest.approx(3.0 * np.sqrt(w[-1]), rel=2e-3)


def test_identify_features_in_the_file_are_coloured_by_their_fate(identify_run):
    _, seen, html = identify_run
    viewer = seen["viewer"]
    fates = [s.nodes["/camera/features"].props["fate"] for s in viewer.steps[1:]]
    for fate, (n, n_matched, n_used) in zip(fates, seen["features"], strict=True):
        # the live view's own count of the most probable model's matches and used inliers
        assert len(fate) == n and int((fate >= 1).sum()) == n_matched and int((fate == 2).sum()) == n_used
    _, messages = recording(html)
    clouds = [m for _, m in messages if m["type"] == "PointCloudMessage" and m["name"] == "/camera/features"]
    colors = np.asarray(clouds[-1]["props"]["colors"], np.uint8).reshape(-1, 3)
    last = next(f for f in reversed(fates) if len(f))
    want = np.array([(150, 150, 150), (255, 150, 0), (0, 200, 0)], np.uint8)[last]
    assert np.array_equal(colors, want)


def test_the_saved_page_is_self_contained(identify_run):
    _, _, html = identify_run
    assert not re.search(r"<script[^>]*\bsrc=", html)  # every script inlined
    assert not re.search(r"<link[^>]*\bhref=[\"']https?:", html)
    urls = set(re.findall(r"https?://[^\s\"'<>)]+", html))
    assert all(u.startswith("http://www.w3.org/") for u in urls), urls  # XML namespaces only


def test_ellipsoid_axes_are_three_sqrt_eigenvalues():
    from lab.viz.view3d import ellipsoid_axes

    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    Sigma = A @ A.T + 0.01 * np.eye(3)
    axes, V = ellipsoid_axes(Sigma)
    assert np.allclose(np.sort(axes), 3.0 * np.sqrt(np.linalg.eigvalsh(Sigma)))
    assert np.allclose(V @ np.diag((axes / 3.0) ** 2) @ V.T, Sigma)


def test_a_missing_viewer_library_is_one_clear_line(tmp_path):
    code = (
        "import sys; sys.modules['viser'] = None\n"
        "from lab.cli import main\n"
        f"sys.exit(main(['identify', '--max-actions', '1', '--view3d', r'{tmp_path / 'v.html'}']))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "pip install 'lab[view3d]'" in lines[0], r.stderr
    assert not (tmp_path / "v.html").exists()


def test_the_view3d_path_must_be_an_html_page(tmp_path):
    from lab.errors import ConfigError
    from lab.viz.view3d import View3D

    with pytest.raises(ConfigError, match="HTML"):
        View3D(tmp_path / "run.rrd")


def test_search_view_has_one_step_per_event_and_the_heat_map_is_the_agents_map(search_run):
    """A short search: one timeline step per event; the floor's heat map at each event is the agent's
    probability map then (its colours decoded from the page), and the global scan's peaks are there."""
    import cv2
    from matplotlib import colormaps

    res, seen, _, page = search_run
    maps, peaks = seen["maps"], seen["peaks"]
    assert len(res.events) == len(maps) >= 1
    _, messages = recording(page.read_text())
    heat = [m for _, m in messages if m["type"] == "ImageMessage" and m["name"] == "/map/heat"]
    assert len(heat) == len(res.events)  # one map per event
    png = heat[-1]["props"]["_data"]  # viser 1.1: the encoded image
    png = np.frombuffer(png, np.uint8) if isinstance(png, bytes) else np.asarray(png, np.uint8)
    img = cv2.cvtColor(cv2.imdecode(png, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    P = maps[-1]
    want = (255 * colormaps["viridis"](np.clip(1 + np.log10(P / P.max()) / 4, 0, 1))[..., :3]).astype(
        np.uint8
    )
    assert np.array_equal(img, want.transpose(1, 0, 2)[::-1])  # x along the columns, y up the rows
    if peaks[-1]:
        clouds = [m for _, m in messages if m["type"] == "PointCloudMessage" and m["name"] == "/map/peaks"]
        assert np.asarray(clouds[-1]["props"]["points"]).size // 3 == peaks[-1]


@pytest.fixture(scope="module")
def search_run(tmp_path_factory):
    """A search long enough for a global scan, a drive and a local search (a timeline of several steps),
    recorded in 3D, with the agent's map, the global scan's peak count and its last local search kept
    at every event (for the test only). Returns the result, what was kept, the page and its path."""
    from lab.runs.search import navigator_factory, run_search

    out = tmp_path_factory.mktemp("view3d_search")
    seen = {"maps": [], "peaks": [], "locals": [], "cameras": []}

    def attach(agent):
        viewer = agent.observer
        capture = agent.robot.capture_stereo

        def capture_and_keep():  # every stereo frame's camera, where the robot's head had it
            f = capture()
            seen["cameras"].append((f.t, (f.odom.G() @ f.G_RC)[:3, 3]))
            return f

        agent.robot.capture_stereo = capture_and_keep

        def observer(a, event):
            viewer(a, event)
            seen["maps"].append(np.array(a.pmap.P, float))
            g = list(getattr(a, "_globals", ()))
            seen["peaks"].append(0 if not g else sum(p.p_W is not None for p in g[-1].peaks))
            seen["locals"].append(a.last_local)
            seen["spec"], seen["robot"] = a.pmap.spec, a.robot

        agent.observer = observer

    res = run_search(
        "toy_block", 3, max_time=40.0, navigate=navigator_factory, view3d=out / "s.html", attach=attach
    )
    return res, seen, (out / "s.html").read_text(), out / "s.html"


def test_search_view_draws_the_map_on_the_shelf_and_table_tops_at_their_height(search_run):
    """Every table and shelf top of the scene carries the map's cells whose centres lie on it (found
    here from the scene file's poses and sizes), at the top's height, in the heat map's colours of the
    agent's map at that event (decoded from the page)."""
    from matplotlib import colormaps

    from lab.scene import load_scene

    res, seen, html, _ = search_run
    _, messages = recording(html)
    spec, P = seen["spec"], seen["maps"][-1]
    X, Y = spec.cell_centers()
    tops = [b for b in load_scene("lab_room").bodies if b.supports]
    assert {b.shape for b in tops} >= {"table", "shelf"}
    want_rgb = (255 * colormaps["viridis"](np.clip(1 + np.log10(P / P.max()) / 4, 0, 1))[..., :3]).astype(
        np.uint8
    )
    for b in tops:
        x, y, z0, yaw = b.pose
        c, s_ = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
        u, v = c * (X - x) + s_ * (Y - y), -s_ * (X - x) + c * (Y - y)  # the cell centres in the body's frame
        on = (np.abs(u) <= b.size[0] / 2 + 1e-6) & (np.abs(v) <= b.size[1] / 2 + 1e-6)  # edges included
        clouds = [
            m
            for _, m in messages
            if m["type"] == "PointCloudMessage" and m["name"] == f"/map/surface/{b.name}"
        ]
        assert len(clouds) == len(res.events), b.name  # redrawn with the map at every event
        pts = np.asarray(clouds[-1]["props"]["points"], np.float32).reshape(-1, 3).astype(float)
        cols = np.asarray(clouds[-1]["props"]["colors"], np.uint8).reshape(-1, 3)
        ij = np.rint((pts[:, :2] - np.asarray(spec.origin_xy)) / spec.resolution - 0.5).astype(int)
        assert sorted(map(tuple, ij)) == sorted(map(tuple, np.argwhere(on))), b.name
        assert np.allclose(pts[:, 2], z0 + b.height + 0.01, atol=2e-3)  # the page keeps points in float16
        assert np.array_equal(cols, want_rgb[ij[:, 0], ij[:, 1]])


def test_search_view_shows_the_local_searchs_views(search_run):
    """One frustum per view of the last local search, each where a stereo frame of that search was
    taken from (the frame's odometry and its head's measured pan and tilt)."""
    res, seen, html, _ = search_run
    local = next((lc for lc in reversed(seen["locals"]) if lc is not None), None)
    assert local is not None and any(e.kind == "local" for e in res.events), "no local search in the run"
    _, messages = recording(html)
    frustums = {}
    for _, m in messages:
        name = m.get("name", "")
        if m["type"] == "CameraFrustumMessage" and name.startswith("/camera/local/"):
            frustums[name] = m
        elif m["type"] == "RemoveSceneNodeMessage" and name.startswith("/camera/local/"):
            frustums.pop(name, None)
    assert len(frustums) == len(local.views) >= 3
    pos = np.array([last_position(messages, n) for n in frustums])
    # each view's camera is where a frame of that local search was taken from (the head's measured state)
    cams = np.array([p for t, p in seen["cameras"] if local.t_start - 1e-6 <= t <= local.t_end + 1e-6])
    assert len(cams) >= len(local.views)
    gap = np.linalg.norm(pos[:, None, :] - cams[None, :, :], axis=2).min(axis=1)
    # drawn from where the robot believed it stood at the end; a landmark correction during the search
    # moves that belief by a centimetre or so, and in the real room's surveyed map (the posters in the
    # background of most views refine it) by a few millimetres at most views
    assert gap.max() < 0.03 and np.median(gap) < 0.005, gap
    assert np.ptp(pos, axis=0).max() > 0.02  # the views differ: the head panned or tilted


def test_a_callers_own_steps_are_written_in_time_order(tmp_path):
    """``add_step`` (the notebooks' one-update views): the caller's nodes on the timeline, decoded from
    the page at their times; a step back in time is refused."""
    from lab.errors import ConfigError
    from lab.viz.view3d import Node, View3D, ellipsoid_mesh

    v = View3D()
    Sigma = np.diag([4e-4, 1e-4, 2.5e-5])
    for t, scale in ((0.0, 1.0), (1.5, 0.25)):
        v.add_step(
            t,
            f"t {t}",
            {
                "/e": Node(
                    "mesh", ellipsoid_mesh((1.0, 2.0, 0.5), scale * Sigma).props | {"color": (0, 0, 255)}
                )
            },
        )
    with pytest.raises(ConfigError, match="go back"):
        v.add_step(1.0, "late", {})
    duration, messages = recording(v.save(tmp_path / "steps.html").read_text())
    assert duration == pytest.approx(1.5 + LAST_STEP_HOLD_S)
    meshes = [(t, m) for t, m in messages if m["type"] == "MeshMessage" and m["name"] == "/e"]
    assert [t for t, _ in meshes] == pytest.approx([0.0, 1.5])
    for (_, m), scale in zip(meshes, (1.0, 0.25), strict=True):
        v_ = np.asarray(m["props"]["vertices"], np.float32).reshape(-1, 3).astype(float) - (1.0, 2.0, 0.5)
        d2 = np.einsum("ij,jk,ik->i", v_, np.linalg.inv(scale * Sigma), v_)  # on the 3-sigma surface
        assert np.allclose(np.sqrt(d2), 3.0, rtol=2e-3)


def test_lab_search_view3d_flag_writes_the_page_and_keeps_stdout_json(tmp_path):
    import json

    page = tmp_path / "views" / "search.html"
    r = subprocess.run(
        [sys.executable, "-m", "lab", "search", "--object", "toy_block", "--seed", "1", "--max-time", "5",
         "--view3d", str(page)],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads(r.stdout)  # nothing of the viewer's on stdout
    assert summary["object"] == "toy_block"
    assert f"wrote the 3D view to {page}" in r.stderr
    duration, messages = recording(page.read_text())
    assert any(m["type"] == "ImageMessage" for _, m in messages)


def test_lab_demo_passes_view3d_to_its_episode_and_names_the_page_in_its_report(tmp_path, monkeypatch):
    """``lab demo --view3d`` reaches the episode (the episode itself is the identify test's), and the
    report tells where the page is."""
    import lab.runs.identify as identify
    from lab.cli.parser import build_parser
    from lab.runs.demo import run_demo

    args = build_parser().parse_args(["demo", "--out", str(tmp_path), "--view3d", str(tmp_path / "v.html")])
    assert args.view3d == tmp_path / "v.html"
    seen = {}

    def fake_identify(*a, **kw):
        seen.update(kw)
        return {"true_model": 1, "identified_model": 1, "success": True, "actions": 0, "sim_time_s": 1.0,
                "wall_time_s": 1.0, "final_posterior": [0.25] * 4, "planner": "lut", "seed": 0,
                "view3d": str(kw["view3d"])}  # fmt: skip

    monkeypatch.setattr(identify, "run_identify", fake_identify)
    monkeypatch.setattr("lab.runs.demo.tables_missing", lambda: [])
    report = run_demo(tmp_path, view3d=args.view3d, say=lambda s: None)
    assert seen["view3d"] == tmp_path / "v.html"
    assert f"`{tmp_path / 'v.html'}`" in report.read_text()


def seek_past_the_end(b) -> None:
    """Show the recording's last step through the page's own time box: a time past the end applies
    every remaining message. The field keeps the focus: leaving it re-sends its value, which viser's
    player (having wrapped its clock to the start) takes as a seek back to the first step. The slider
    cannot do it: its value is rounded to 1e-4 s, below a duration that sums float steps."""
    b.evaluate(
        "(i => { i.focus(); i.select(); return 1 })(document.querySelector('.mantine-NumberInput-input'))"
    )
    b.send("Input.insertText", {"text": "99999"})


@pytest.mark.parametrize("which", ["identify", "search"])
def test_the_page_plays_offline_in_chromium_and_its_last_step_is_not_its_first(which, request, tmp_path):
    """The saved page in headless Chromium, every request off this machine failed and recorded: the
    scene draws (not a blank canvas), and scrubbing from the first step to the last changes the
    picture. The last step's picture is kept (tests/browser.py: screenshot_dir)."""
    from browser import Browser, chromium_or_skip, screenshot_dir

    chromium = chromium_or_skip()
    if which == "identify":
        page = tmp_path / "identify.html"
        page.write_text(request.getfixturevalue("identify_run")[2])
    else:
        page = request.getfixturevalue("search_run")[3]
    with Browser(size=(960, 640), timeout=240, chromium=chromium) as b:
        b.open(page)
        b.wait_for("document.querySelector('canvas') && document.querySelector('.mantine-Slider-track')")
        b.evaluate("document.querySelectorAll('.mantine-Notification-closeButton').forEach(e => e.click())")
        scene = b.rect("canvas")  # the 3D canvas; the time bar is docked below it
        track = b.rect(".mantine-Slider-track")
        y = track["y"] + track["height"] / 2
        b.drag((track["x"] + track["width"] / 2, y), (track["x"] - 40, y))  # scrub back to the start
        first = b.settled_screenshot(scene)
        seek_past_the_end(b)
        last = b.settled_screenshot(scene, path=screenshot_dir() / f"view3d_{which}_last.png")
        assert b.blocked == [] and b.errors == [], (b.blocked, b.errors)
    assert first.std() > 10 and last.std() > 10  # a scene, not a blank canvas
    moved = np.abs(first.astype(int) - last.astype(int)).max(axis=2) > 30
    assert moved.mean() > 0.001  # the run played: the head, its frustum, the ring, the labels moved
