"""Write the notebooks from their cells here, without outputs (run from the repository root).

    python notebooks/make_notebooks.py

Each notebook is a list of ("md" | "code", text) cells. Keeping the source here makes diffs readable and
guarantees the committed notebooks carry no outputs; the tests execute them headless with LAB_FAST=1.
"""

from __future__ import annotations

from pathlib import Path

import nbformat

HERE = Path(__file__).resolve().parent

SETUP = """\
import os
import math
import numpy as np
import matplotlib.pyplot as plt
%matplotlib inline
FAST = os.environ.get("LAB_FAST") == "1"   # CI runs the notebooks quickly with LAB_FAST=1
"""

NB00 = [
    (
        "md",
        r"""# 00 The simulator and stereo

The robot of both papers has a **stereo camera on a pan-tilt unit**. Everything it knows about the
world comes from pairs of images: features found in both images, matched along the same row, and
turned into 3D points by triangulation. This notebook builds that pipeline step by step and checks
each step against the simulator's ground truth.

Conventions (frames, angles, units) are written down once in `docs/conventions.md`: the camera frame
$C$ is the left camera's optical frame, $x$ right, $y$ down, $z$ forward.""",
    ),
    ("code", SETUP),
    (
        "md",
        r"""## The world and the robot

A world is a scene file (`worlds/lab_room.toml`) loaded into PyBullet. `SimRobot` is the simulated
robot behind the same `Robot` interface as the real one: capture a stereo pair, drive, move the head.""",
    ),
    (
        "code",
        """\
from lab.geometry import Pose2D
from lab.sim import SimWorld, SimRobot, load_box_models

world = SimWorld("box_database")
model = load_box_models()[1]
carrier = world.add_carrier(model, Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi)   # unique face towards -x
robot = SimRobot(world, start=Pose2D(-1.0, 0.05, 0.0))
robot.enable()
robot.command_pan_tilt(0.0, math.radians(-12))
robot.wait_pan_tilt()
frame = robot.capture_stereo()
cam = frame.camera
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
ax[0].imshow(frame.left); ax[0].set_title("left")
ax[1].imshow(frame.right); ax[1].set_title("right")
for a in ax:
    a.axis("off")
""",
    ),
    (
        "md",
        r"""## The pinhole model

A point $(X, Y, Z)$ in $C$ lands on pixel

$$u = f_x \frac{X}{Z} + c_x, \qquad v = f_y \frac{Y}{Z} + c_y .$$

For a rendered image of height $H$ and vertical field of view $\theta$: $f = \frac{H/2}{\tan(\theta/2)}$,
$c_x = W/2 - 0.5$, $c_y = H/2 - 0.5$ (pixel centres at integer coordinates). We check it: the box's
centre, projected with these numbers, should fall in the middle of the box in the image.""",
    ),
    (
        "code",
        """\
from lab.geometry import se3_inv, transform_points

print(f"f = {cam.fx:.2f} px, c = ({cam.cx}, {cam.cy}) px, baseline {cam.baseline} m")
G_WC = world.truth.G_WC()                       # ground truth: for checking only
centre_C = transform_points(se3_inv(G_WC), carrier.G_WO[:3, 3])
u, v = cam.project(centre_C)[0]
seg = world.truth.segmentation(G_WC, cam) == world.body_id("target")
vv, uu = np.nonzero(seg)
print(f"projected centre ({u:.1f}, {v:.1f}); the box's pixels span u {uu.min()}..{uu.max()}, v {vv.min()}..{vv.max()}")
assert uu.min() < u < uu.max() and vv.min() < v < vv.max()
plt.imshow(frame.left); plt.plot(u, v, "r+", ms=20); plt.axis("off");
""",
    ),
    (
        "md",
        r"""## SIFT features and matches along epipolar rows

The pair is *rectified*: a point appears on the same row $v$ in both images, shifted left in the right
image by the **disparity** $d = u_L - u_R > 0$. So a left feature's match is searched only on its row,
and must pass Lowe's ratio test (the best descriptor clearly better than the second best).""",
    ),
    (
        "code",
        """\
from lab.vision import stereo_features

f3d = stereo_features(frame.left, frame.right, cam)
print(f"{len(f3d)} matched 3D features")
both = np.hstack([frame.left, frame.right])
plt.figure(figsize=(11, 4)); plt.imshow(both)
for (ul, vl), d in zip(f3d.uv, f3d.disparity, strict=True):
    plt.plot([ul, ul - d + cam.width], [vl, vl], "-", lw=0.6)
plt.axis("off"); plt.title("matches: same row, shifted by the disparity");
""",
    ),
    (
        "md",
        r"""## Triangulation

With baseline $B$, similar triangles give depth from disparity, then $X$ and $Y$ from the pinhole model:

$$Z = \frac{f B}{d}, \qquad X = \frac{(u - c_x) Z}{f}, \qquad Y = \frac{(v - c_y) Z}{f}.$$

**Exercise.** At $f = 207.8$ px and $B = 0.12$ m, what depth does a disparity of 25 px give? How much
does the depth change if the disparity is off by 0.5 px?""",
    ),
    (
        "code",
        """\
depth = world.truth.depth(G_WC, cam)        # ground truth depth buffer, for checking
on_box = seg[np.round(f3d.uv[:, 1]).astype(int), np.round(f3d.uv[:, 0]).astype(int)]
uv = f3d.uv[on_box]
z_true = depth[np.round(uv[:, 1]).astype(int), np.round(uv[:, 0]).astype(int)]
p_true = np.stack([(uv[:, 0] - cam.cx) * z_true / cam.fx, (uv[:, 1] - cam.cy) * z_true / cam.fy, z_true], 1)
err_mm = 1e3 * np.linalg.norm(f3d.points_C[on_box] - p_true, axis=1)
print(f"{on_box.sum()} features on the box: median 3D error {np.median(err_mm):.1f} mm")
assert np.median(err_mm) < 15
plt.hist(err_mm, bins=20); plt.xlabel("3D error [mm]"); plt.ylabel("features");
""",
    ),
    (
        "md",
        r"""## How uncertain is a stereo point?

Propagating pixel noise $\sigma_u$ and disparity noise $\sigma_d$ through the triangulation gives each
point a covariance $\Sigma = J \,\mathrm{diag}(\sigma_u^2, \sigma_u^2, \sigma_d^2)\, J^T$. Its depth part
is $\sigma_Z = \frac{Z^2}{f B}\sigma_d$: it grows with the **square** of the distance. That is why the EKF
later trusts near features more. Move the slider.""",
    ),
    (
        "code",
        """\
import ipywidgets as widgets

def sigma_z_mm(Z, sigma_d=0.4):
    return 1e3 * Z**2 * sigma_d / (cam.fx * cam.baseline)

out = widgets.Output()
slider = widgets.FloatSlider(value=1.0, min=0.5, max=4.0, step=0.1, description="depth [m]")

def show(change=None):
    with out:
        out.clear_output(wait=True)
        Z = np.linspace(0.5, 4.0, 50)
        plt.figure(figsize=(5, 3)); plt.plot(Z, sigma_z_mm(Z)); plt.axvline(slider.value, color="r")
        plt.xlabel("depth Z [m]"); plt.ylabel("sigma_Z [mm]"); plt.show()
        print(f"at {slider.value:.1f} m: sigma_Z = {sigma_z_mm(slider.value):.1f} mm")

slider.observe(show, names="value")
show()
widgets.VBox([slider, out])
""",
    ),
    (
        "code",
        """\
# the covariances the pipeline attached to each feature follow that law
Z = f3d.points_C[:, 2]
assert np.allclose(np.sqrt(f3d.covariances[:, 2, 2]), sigma_z_mm(Z) / 1e3, rtol=1e-9)
world.close()
""",
    ),
]

NB01 = [
    (
        "md",
        r"""# 01 The pose EKF

Both papers estimate an object's 6-DOF pose with an extended Kalman filter. The state is the object's
pose in the camera frame, $X = [x, y, z, \alpha, \beta, \gamma]$ (translation, then z-y-x Euler angles).
A measured 3D feature $d_j$ matched to database feature $b_{J(j)}$ (known in the object frame) is
predicted by the **measurement model**, Eq. (3) of the identification paper:

$$d_j = x_r + R(x_o)\, b_{J(j)} + \xi, \qquad R(x_o) = R_z(\alpha) R_y(\beta) R_x(\gamma).$$""",
    ),
    ("code", SETUP),
    (
        "code",
        """\
from lab.estimation import measurement_model, measurement_jacobian
from lab.estimation.synthetic import box_surface_points

rng = np.random.default_rng(0)
b_O, normals = box_surface_points(rng, 6)            # points on a 0.28 m box, in its own frame O
X = np.array([0.05, -0.02, 1.0, 0.3, -0.2, 0.1])     # a pose of O in C
d = measurement_model(X, b_O)
print("first predicted points in C:\\n", d[:3].round(3))
""",
    ),
    (
        "md",
        r"""## The Jacobian $C = \partial H / \partial X$

The EKF linearises the measurement model. For each feature the $3 \times 6$ block is
$C_j = [\,I_3 \;\; \partial (R b_j)/\partial x_o\,]$. A Jacobian must agree with finite differences:""",
    ),
    (
        "code",
        """\
C = measurement_jacobian(X, b_O)
eps = 1e-6
C_fd = np.column_stack([(measurement_model(X + eps * e, b_O) - measurement_model(X - eps * e, b_O)).ravel() / (2 * eps)
                        for e in np.eye(6)])
print("largest difference:", np.abs(C - C_fd).max())
assert np.allclose(C, C_fd, atol=1e-7)
""",
    ),
    (
        "md",
        r"""## Predict and update, step by step

*Predict* moves the estimate with the robot's and the camera's motion (Eq. (1)-(2)) and grows the
covariance by the process noise: $\bar\mu = F(\mu, u)$, $\bar\Sigma = F \Sigma F^T + Q$.
*Update* corrects it with the measurements:

$$y = D - H(\bar\mu), \quad S = C \bar\Sigma C^T + \Sigma_m, \quad K = \bar\Sigma C^T S^{-1},$$
$$\mu = \bar\mu + K y, \quad \Sigma = (I - K C)\bar\Sigma (I - K C)^T + K \Sigma_m K^T \;\text{(Joseph form)}.$$

We run it on real features from rendered stereo pairs, matched against the box's trained database.
The filter starts itself from the first frame by RANSAC on the matches.""",
    ),
    (
        "code",
        """\
from lab.estimation import EKFConfig, OrientationChart, PoseEKF
from lab.geometry import Pose2D, se3_inv
from lab.sim import SimWorld, SimRobot, load_box_models
from lab.vision import Matcher, get_database, stereo_features

model = load_box_models()[0]
db = get_database(model.name)
world = SimWorld("box_database")
carrier = world.add_carrier(model, Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi - 0.4)
robot = SimRobot(world, start=Pose2D(-1.1, 0.1, 0.0)); robot.enable()
robot.command_pan_tilt(-0.09, math.radians(-11)); robot.wait_pan_tilt()
ekf = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(1))
matcher = Matcher(db)
errors = []
for _ in range(8 if FAST else 20):
    frame = robot.capture_stereo()
    f = stereo_features(frame.left, frame.right, frame.camera)
    ekf.predict(frame.G_RC, frame.G_RC, np.eye(4), 0.1)
    result = ekf.update(*matcher.match(f).pairs(f, db))
    G_CO_true = se3_inv(world.truth.G_WC()) @ carrier.G_WO      # ground truth, for the plot only
    errors.append(np.linalg.norm(ekf.estimate.mu[:3] - G_CO_true[:3, 3]))
    robot.step(0.1)
print(result.outcome, result.reason, f"- {result.n_used} of {result.n_matches} matches used")
plt.plot(np.array(errors) * 100, "o-"); plt.xlabel("frame"); plt.ylabel("position error [cm]");
assert errors[-1] < 0.02
""",
    ),
    (
        "md",
        r"""## The same filter in filterpy

A filter written from the equations should agree with an independent implementation. filterpy's
`ExtendedKalmanFilter` (Joseph form too) on the same inputs:""",
    ),
    (
        "code",
        """\
from filterpy.kalman import ExtendedKalmanFilter

mu0 = np.array([0.0, 0.0, 1.1, 0.2, 0.1, -0.1]); P0 = np.diag([0.02] * 3 + [0.05] * 3)
truth = mu0 + np.array([0.01, -0.01, 0.02, 0.02, -0.01, 0.02])
d_true = measurement_model(truth, b_O)
Sigma_d = np.array([0.003**2 * np.eye(3)] * len(b_O))
z = d_true + rng.normal(0, 0.003, d_true.shape)

ours = PoseEKF(rng=np.random.default_rng(0)); ours.initialize(mu0, P0)
ours.update(z, b_O, Sigma_d)

fp = ExtendedKalmanFilter(dim_x=6, dim_z=3 * len(b_O))
fp.x, fp.P, fp.R = mu0.copy(), P0.copy(), np.kron(np.eye(len(b_O)), 0.003**2 * np.eye(3))
fp.update(z.ravel(), lambda x: measurement_jacobian(x, b_O), lambda x: measurement_model(x, b_O).ravel())
print("state difference:", np.abs(ours.estimate.mu - fp.x).max())
assert np.allclose(ours.estimate.mu, fp.x, atol=1e-9) and np.allclose(ours.Sigma, fp.P, atol=1e-9)
world.close()
""",
    ),
    (
        "md",
        r"""## Exercise

1. Flip the sign of one column of the Jacobian and run the finite-difference check again: what fails?
2. Why does the robot use `OrientationChart.ROTATION_VECTOR`? (Hint: what is $\beta$ when the camera
   looks straight at the box's $x$ face? Look up *gimbal lock*.)""",
    ),
]


NB03 = [
    (
        "md",
        r"""# 03 Grid search

The search paper's robot is told *which* object to find (a cereal box, a book, a toy block), but not
*where* it is. It keeps a **probability map** of the floor and looks where the object most probably is:

1. a coarse **global search**: the head turns around, patches whose colours look like the object are
   found in the images, and the map cells they lie on become more probable;
2. the robot drives to the most probable cell, on a **costmap** built from stereo, along an **A\***
   path;
3. a fine **local search** there: SIFT features and the pose EKF of notebook 01. Found: done, with the
   object's 6D pose. Not found: that cell becomes less probable, and the robot goes to the next peak.

This notebook builds each piece from the paper's equations (*A Probabilistic Framework for
Stereo-Vision Based 3D Object Search with 6D Pose Estimation*, "the search paper") and then runs the
whole search in the simulated lab room.

**Notation.** The floor is cut into square cells $c_{ij}$ (20 cm, the paper's size). At step $k$ the
robot makes a binary measurement $y^k_{uv} \in \{0, 1\}$: "I looked at cell $c_{uv}$ and did ($1$) or did
not ($0$) detect the object". $\mathbf{Y}_{1:k}$ are all the measurements up to step $k$. The hypothesis
$h^k_{ij} = 1$ says "the object is in cell $c_{ij}$". The **probability map** $M_p$ holds
$P(h_{ij} = 1 \mid \mathbf{Y}_{1:k})$ for every cell; the object is in exactly one cell, so the map sums
to 1.""",
    ),
    ("code", SETUP),
    (
        "md",
        r"""## The Bayes update, Eqs. (1)-(3)

After a measurement $y_{uv}$ of cell $c_{uv}$, Bayes' rule gives every cell's new probability (the object
does not move, so the map before the measurement is the prior):

$$P(h_{ij}=1 \mid \mathbf{Y}_{1:k}) = \frac{P(y_{uv} \mid h_{ij}=1)\; P(h_{ij}=1 \mid \mathbf{Y}_{1:k-1})}
{P(y_{uv} \mid \mathbf{Y}_{1:k-1})} \qquad (1)$$

The **detection model** says how the detector errs. $\alpha$ is the probability of a *false alarm* (it
says "yes" about a cell the object is not in), $\beta$ the probability of a *missed detection* (it says
"no" about the object's cell):

$$P(y_{uv}=0 \mid h_{ij}=1) = \begin{cases}\beta & (u,v) = (i,j)\\ 1-\alpha & (u,v)\ne(i,j)\end{cases},
\qquad P(y_{uv}=1 \mid h_{ij}=1) = 1 - P(y_{uv}=0 \mid h_{ij}=1) \qquad (2)$$

The denominator is the numerator summed over all cells, so that the map sums to 1 again:

$$P(y_{uv} \mid \mathbf{Y}_{1:k-1}) = \sum_{m,n} P(y_{uv} \mid h_{mn}=1)\; P(h_{mn}=1 \mid \mathbf{Y}_{1:k-1})
\qquad (3)$$

We compute one update by hand on a small map of 8 x 6 cells, starting from the uniform prior
$P_0 = 1/48$, and compare it with the library's `update`.""",
    ),
    (
        "code",
        """\
from lab.navigation import GridSpec
from lab.search import update

small = GridSpec.from_bounds(0.0, 0.0, 1.6, 1.2, 0.2)       # 1.6 x 1.2 m of floor in 20 cm cells: 8 x 6
P0 = np.full(small.shape, 1.0 / small.n_cells)               # the uniform prior P_0
alpha, beta = 0.1, 0.2
u, v = 3, 2                                                  # we searched cell c_32 and saw nothing: y = 0

L = np.full(small.shape, 1 - alpha)                          # Eq. (2), y = 0: 1 - alpha on the other cells ...
L[u, v] = beta                                               # ... and beta on the searched one
evidence = (L * P0).sum()                                    # Eq. (3)
P1_by_hand = L * P0 / evidence                               # Eq. (1)

P1 = update(P0, (u, v), 0, alpha, beta)                      # the library
assert np.allclose(P1, P1_by_hand) and np.isclose(P1.sum(), 1.0)
print(f"searched cell: {P0[u, v]:.4f} -> {P1[u, v]:.4f};  every other cell: {P0[0, 0]:.4f} -> {P1[0, 0]:.4f}")
""",
    ),
    (
        "md",
        r"""**A failed search moves probability.** Write $p$ for the searched cell's probability before a miss.
By Eqs. (1)-(3) it becomes $\frac{\beta p}{\beta p + (1-\alpha)(1-p)}$, and every other cell is multiplied
by the same factor $\frac{1-\alpha}{\beta p + (1-\alpha)(1-p)} > 1$: the searched cell's mass flows to
all the others, in proportion to what they hold. Searching the same cell $n$ times without success
leaves it

$$p_n = \frac{\beta^n p}{\beta^n p + (1-\alpha)^n (1-p)} .$$

Move the sliders: $\alpha$, $\beta$, how often the cell is searched, and what the detector says.""",
    ),
    (
        "code",
        """\
import ipywidgets as widgets
from lab.errors import ConfigError

def repeated(P, cell, y, alpha, beta, n):
    \"\"\"The map after n detections y of the same cell, and that cell's probability after each.\"\"\"
    history = [P[cell]]
    for _ in range(n):
        P = update(P, cell, y, alpha, beta)
        history.append(P[cell])
    return P, np.array(history)

out = widgets.Output()
a_slider = widgets.FloatSlider(value=0.1, min=0.01, max=0.5, step=0.01, description="alpha")
b_slider = widgets.FloatSlider(value=0.2, min=0.01, max=0.9, step=0.01, description="beta")
n_slider = widgets.IntSlider(value=3, min=0, max=10, description="searches")
y_toggle = widgets.ToggleButtons(options=[("not found, y = 0", 0), ("found, y = 1", 1)], value=0)

def show(change=None):
    with out:
        out.clear_output(wait=True)
        try:
            P, hist = repeated(P0, (u, v), y_toggle.value, a_slider.value, b_slider.value, n_slider.value)
        except ConfigError as e:                    # alpha + beta >= 1: the library says why it refuses
            print("refused:", e)
            return
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.2))
        im = ax[0].imshow(P.T, origin="lower", extent=small.extent, cmap="viridis")
        ax[0].plot(*small.cell_to_world(u, v), "rx", ms=12, mew=2)
        ax[0].set_title(f"M_p after {n_slider.value} detections y = {y_toggle.value} of the red cell")
        fig.colorbar(im, ax=ax[0])
        ax[1].plot(hist, "o-"); ax[1].set_ylim(0, 1.02)
        ax[1].set_xlabel("searches of the cell"); ax[1].set_ylabel("P(h_uv = 1 | Y)")
        plt.show()

for w in (a_slider, b_slider, n_slider, y_toggle):
    w.observe(show, names="value")
show()
widgets.VBox([widgets.HBox([a_slider, b_slider, n_slider]), y_toggle, out])
""",
    ),
    (
        "code",
        """\
# the closed form for n misses agrees with n Bayes updates
p = P0[u, v]
for n in (1, 4, 10):
    _, hist = repeated(P0, (u, v), 0, alpha, beta, n)
    p_n = beta**n * p / (beta**n * p + (1 - alpha) ** n * (1 - p))
    assert np.isclose(hist[-1], p_n), (n, hist[-1], p_n)
print("p_n after 1, 4, 10 misses:", [f"{repeated(P0, (u, v), 0, alpha, beta, n)[1][-1]:.2e}" for n in (1, 4, 10)])
""",
    ),
    (
        "md",
        r"""**Exercise.**

1. Set $\beta$ close to 0. What does one miss do to the searched cell? Why is that dangerous for an
   object the local search cannot see well (the paper's glossy penguin cup)?
2. The library refuses $\alpha + \beta \ge 1$. Show with Eq. (2) that for such a detector a *positive*
   detection ($y = 1$) would make the detected cell *less* probable.

## The global search's growing $\beta$

The coarse colour search (next section) finds patches of object-like colour, each with a strength
$P'_n \in [0, 1]$, and puts each onto a cell $c_{uv}$ by stereo. The paper treats a patch as a positive
detection, $y_{uv} = 1$, with $P(y_{uv}=1 \mid h_{uv}=1) = P'_n$, that is $\beta_0 = 1 - P'_n$ at that cell,
and lets $\beta$ "increase exponentially for neighbouring cells": stereo ranges at 3-5 m are off by
10-40 cm, so the object may well be in a neighbour. With $d$ the distance [m] from $c_{uv}$ and a growth
length $\lambda$ [m], the library's law is

$$\beta(d) = \min\left(1-\alpha,\; \beta_0\, e^{d/\lambda}\right):$$

the detection likelihood $1 - \beta(d)$ falls from $P'_n$ at the cell to the false-alarm rate $\alpha$ at
$d = \lambda \ln\frac{1-\alpha}{\beta_0}$, and beyond that it *is* Eq. (2)'s "other cell". The global search
uses $\alpha = 0.05$ and $\lambda = 0.2$ m, and never lets $\beta_0$ drop below 0.1.""",
    ),
    (
        "code",
        """\
from lab.search import GlobalSearchConfig, growing_beta_field
from lab.search.trial import map_spec
from lab.sim.scene import load_scene

scene = load_scene("lab_room")           # the search paper's laboratory: 6 x 8 m, tables, a shelf, obstacles
room = map_spec(scene)                   # M_p's grid: the room's floor in 20 cm cells
gcfg = GlobalSearchConfig()              # alpha = 0.05, lambda = growth_m = 0.2 m, beta_min = 0.1
cell = room.world_to_cell(1.0, 1.0)
X, Y = room.cell_centers()
d = np.hypot(X - room.cell_to_world(*cell)[0], Y - room.cell_to_world(*cell)[1])   # distance from c_uv [m]

fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
for P_n in (0.9, 0.7, 0.5):
    beta0 = max(gcfg.beta_min, 1 - P_n)
    B = growing_beta_field(room, cell, gcfg.alpha, beta0, gcfg.growth_m)
    reach = gcfg.growth_m * math.log((1 - gcfg.alpha) / beta0)
    assert np.isclose(1 - B[cell], P_n) and np.allclose(1 - B[d > reach + 1e-9], gcfg.alpha)
    order = np.argsort(d.ravel())
    ax[0].plot(d.ravel()[order], (1 - B).ravel()[order], ".-", label=f"P'_n = {P_n} (reach {reach:.2f} m)")
    if P_n == 0.9:
        im = ax[1].imshow((1 - B).T, origin="lower", extent=room.extent, cmap="magma")
        fig.colorbar(im, ax=ax[1]); ax[1].set_title("P(y=1 | h_ij = 1) for P'_n = 0.9")
ax[0].set_xlim(0, 1); ax[0].set_xlabel("distance from the measured cell [m]"); ax[0].set_ylabel("1 - beta(d)")
ax[0].legend();
""",
    ),
    (
        "md",
        r"""## Colour back-projection (Sec. III-B)

How does a camera image say "the object may be there"? By colour. A pixel's colour $(R, G, B)$ becomes
its **chromaticity**

$$r = \frac{R}{R+G+B}, \qquad g = \frac{G}{R+G+B},$$

which ignores brightness, so a shaded side of the object has the same $(r, g)$ as a lit one. Counting
the chromaticities of many pixels in $32 \times 32$ bins gives a 2D histogram. During training the
robot recorded the **model histogram** $M(c)$ of the object's own pixels (bins $c$, normalised to sum
to 1); it is stored with the object's SIFT database. $I(c)$ is the histogram of what the robot sees now.

The paper back-projects $M$: every pixel gets $M$ of its bin. Grey walls and floors have a lot of
pixels in the same few bins as the white and grey parts of a printed box, so they light up too. The
library back-projects the **ratio** of the two histograms (after Swain and Ballard), scaled so that the
most object-like colour gets 1:

$$\rho(c) = \frac{M(c) / (I(c) + \epsilon)}{\max_{c'} M(c') / (I(c') + \epsilon)}, \qquad
b(u, v) = \rho\big(c(u, v)\big)$$

($\epsilon$ keeps a colour the image hardly holds from dominating). A colour common on the object and
rare in the room scores near 1. Then a **fixed window** of $w \times w$ pixels averages $b$ into $s(u, v)$,
the fraction of the window that looks like the object, and the $N_{hist}$ strongest **clusters** (the
maximum, then the next maximum at least a suppression radius away, ...) are the candidate places, with
strengths $P'_n = s$ at their centres.

The robot stands in the middle of the room facing $+y$ and turns its head 55 degrees to the right. We
search for the cereal box.""",
    ),
    (
        "code",
        """\
from lab.geometry import Pose2D
from lab.search import ProbabilityMap, search_database
from lab.search.global_search import object_likelihood_ratio, process_view, strongest_clusters, window_mean
from lab.sim import RenderSettings, SimRobot, SimWorld
from lab.vision.colour import back_project, chromaticity, colour_histogram

db = search_database("cereal_box")        # SIFT features and the colour model M, trained once and cached
world = SimWorld(scene, RenderSettings(supersample=2))
robot = SimRobot(world, start=Pose2D(0.0, 0.0, math.pi / 2), seed=0)
robot.enable()
robot.command_pan_tilt(math.radians(-55), 0.0)
robot.wait_pan_tilt()
frame = robot.capture_stereo()

bins = db.histogram.shape[0]
M = db.histogram / db.histogram.sum()                              # the model histogram M(c)
I = colour_histogram(frame.left, bins=bins); I = I / I.sum()       # what the robot sees, I(c)
rho = M / (I + gcfg.ratio_eps); rho = rho / rho.max()              # the ratio rho(c)
rg = chromaticity(frame.left)                                      # (H, W, 2): r and g of every pixel
bin_of = np.minimum((rg * bins).astype(int), bins - 1)             # each pixel's bin c(u, v)
b = rho[bin_of[..., 0], bin_of[..., 1]]                            # the back-projection b(u, v)

rho_lib = object_likelihood_ratio(db.histogram, colour_histogram(frame.left, bins=bins), gcfg.ratio_eps)
assert np.allclose(b, back_project(frame.left, rho_lib), atol=1e-5)   # the library's, step by step

s = window_mean(b, gcfg.window_px)                                 # w x w window mean s(u, v)
clusters = strongest_clusters(s, gcfg.n_hist, gcfg.min_strength, gcfg.suppression_px)
print("clusters (u, v, P'_n):", [(u_, v_, round(p_, 2)) for u_, v_, p_ in clusters])

fig, ax = plt.subplots(1, 4, figsize=(15, 3.2))
ax[0].imshow(frame.left); ax[0].set_title("left image")
for u_, v_, p_ in clusters:
    ax[0].add_patch(plt.Circle((u_, v_), 10, fill=False, color="red", lw=2))
ax[1].imshow(rho, origin="lower", extent=(0, 1, 0, 1), cmap="magma"); ax[1].set_title("rho(r, g)")
ax[1].set_xlabel("g"); ax[1].set_ylabel("r")
ax[2].imshow(b, cmap="gray", vmin=0, vmax=1); ax[2].set_title("back-projection b")
ax[3].imshow(s, cmap="gray", vmin=0, vmax=1); ax[3].set_title(f"window mean s ({gcfg.window_px} px)")
for a in (ax[0], ax[2], ax[3]):
    a.axis("off")
""",
    ),
    (
        "md",
        r"""**From a cluster to a map cell.** The cluster's disparity $d$ (the median dense-stereo disparity of
its most object-like pixels) gives its point $p_C$ in the camera frame by the triangulation of notebook
00, and the world point is

$$p_W = G_{WR}\, G_{RC}\, p_C ,$$

with $G_{WR}$ the robot's pose from odometry and $G_{RC}$ the camera on the pan-tilt head at its current
angles. A point at a height where an object can stand, inside the room, is a positive detection of its
cell with the growing $\beta$ above. `process_view` does this for one view; the global search does it for
12 views (6 pans at 2 tilts) and uses the whole scan's histogram as $I$.""",
    ),
    (
        "code",
        """\
pmap = ProbabilityMap(room)                       # uniform P_0 over the room
view = process_view(frame, rho_lib, "rg", pmap, gcfg)
for p in view.peaks:
    where = "" if p.p_W is None else f"p_W = {np.round(p.p_W, 2)}"
    print(f"P'_n = {p.strength:.2f}  {where}  cell {p.cell}: {p.reason}")
    if p.used:
        pmap.update_global(p.cell, p.strength, gcfg.alpha, gcfg.growth_m, gcfg.beta_min)

true_xy = np.array(scene.body("cereal_box").pose[:2])        # the scene file's placement: for checking only
best = max(view.peaks, key=lambda p: p.strength if p.used else -1)
err = np.linalg.norm(best.p_W[:2] - true_xy)
print(f"strongest peak {err * 100:.0f} cm from the cereal box; its cell now holds P = {pmap.P[best.cell]:.3f} "
      f"(uniform: {1 / room.n_cells:.4f})")
assert best.used and err < 0.25 and pmap.peak() == best.cell
plt.figure(figsize=(4, 5))
plt.imshow(pmap.P.T, origin="lower", extent=room.extent); plt.colorbar(label="P(h_ij = 1)")
plt.plot(*true_xy, "r+", ms=14, mew=2); plt.title("M_p after one view (red +: the true box)");
""",
    ),
    (
        "md",
        r"""**Exercise.**

1. Back-project the plain model histogram, $M / \max M$, instead of $\rho$ (`back_project(frame.left, db.histogram)`).
   What lights up now?
2. The fire extinguisher on the right is red, like the box. Print $b$ on its pixels. Why does it score
   so little? (Look at where its pixels fall in $\rho(r, g)$.)

## The costmap and A* (Sec. III-D)

To drive to a peak without hitting anything, the robot builds a second grid, the **costmap** $M_c$
(10 cm cells). Dense stereo gives 3D points $p_W$; a plane fitted to the floor points gives each point's
height $h$ above the floor. A point with $|h| \le 3$ cm is floor; one from 5 cm up to the robot's height
(plus a margin) is an obstacle: a table top at 0.75 m is one, because the head would hit it. A cell is
*obstacle* when obstacle points fell in it (obstacle wins over floor, the paper's conservative rule),
*free* when only floor points did, and *unknown* otherwise. Obstacles are then **grown** by the robot's
radius, so that A* can plan for a point.

A* searches the 8-connected grid. A step from cell $u$ into its neighbour $v$ costs
$c(u, v) = \ell(u, v)\, m(v)$, with $\ell = r$ or $\sqrt 2\, r$ ($r$ the cell size) and a multiplier
$m(v) \ge 1$: 1 on seen floor, 2 in unknown cells, more close to obstacles, $\infty$ inside grown ones.
Its heuristic, the octile distance $h(n) = m_{min}\, r\, (\Delta_{max} + (\sqrt 2 - 1)\, \Delta_{min})$
($\Delta$: the cell offsets from $n$ to the goal), never overestimates the remaining cost, so the path
A* returns is a cheapest one.

The robot looks around with its head tilted down, and the navigator builds the costmap:""",
    ),
    (
        "code",
        """\
from scipy.ndimage import binary_dilation
from lab.navigation import CellState, Navigator

nav = Navigator(robot)
pans_deg = (-100, -50, 0, 50) if FAST else (-150, -100, -50, 0, 50, 100, 150)
nav.scan(pans=[math.radians(a) for a in pans_deg])
state = nav.costmap.state
cm = nav.costmap.config
truth = world.truth.occupancy(nav.spec, cm.obstacle_min_height, cm.obstacle_max_height)   # for checking only
obstacle = state == CellState.OBSTACLE
near_truth = binary_dilation(truth)            # a true obstacle's cell or a neighbour of one
seen = state != CellState.UNKNOWN
grid = nav.planning_grid()                     # obstacles grown by the robot's radius, cost multipliers m(v)
print(f"{obstacle.sum()} obstacle cells, {np.mean(near_truth[obstacle]):.0%} of them at a true obstacle; "
      f"{np.sum(truth & (state == CellState.FREE))} truly occupied cells labelled free")
assert obstacle.sum() > 10 and np.mean(near_truth[obstacle]) > 0.9
assert np.all(np.isinf(grid.cost[truth & seen]))   # whatever it has seen of an obstacle, A* will not enter
""",
    ),
    (
        "code",
        """\
import networkx as nx
from lab.navigation import astar_to_region

start, goal = robot.odometry(), (1.6, -1.6)
path = astar_to_region(grid, start, goal, max_distance=0.3)
print(f"A*: {path.status.value}, {path.length:.2f} m long, cost {path.cost:.2f}, {path.expanded} cells expanded")

# an independent peer: Dijkstra (networkx) on the same graph, with every cell within 0.3 m of the goal a goal
ok = np.isfinite(grid.cost)
G = nx.DiGraph()
for i, j in np.argwhere(ok):
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            a, b_ = i + di, j + dj
            if (di, dj) == (0, 0) or not (0 <= a < ok.shape[0] and 0 <= b_ < ok.shape[1]) or not ok[a, b_]:
                continue
            if di and dj and not (ok[i + di, j] and ok[i, j + dj]):
                continue                   # no cutting corners
            G.add_edge((i, j), (a, b_), weight=(math.sqrt(2) if di and dj else 1.0) * grid.spec.resolution * grid.cost[a, b_])
gx, gy = grid.spec.cell_centers()
for i, j in np.argwhere(ok & (np.hypot(gx - goal[0], gy - goal[1]) <= 0.3)):
    G.add_edge((i, j), "goal", weight=0.0)
peer = nx.dijkstra_path_length(G, grid.spec.world_to_cell(start.x, start.y), "goal")
print(f"Dijkstra: cost {peer:.2f}")
assert path.found and np.isclose(path.cost, peer)

x0, x1, y0, y1 = nav.spec.extent
shade = np.choose(state.astype(int), [0.5, 0.0, 1.0])               # unknown grey, free black, obstacle white
plt.figure(figsize=(5, 6))
plt.imshow(shade.T, origin="lower", extent=nav.spec.extent, cmap="gray", vmin=0, vmax=1)
plt.contour(gx, gy, (~ok).astype(float), [0.5], colors="orange", linewidths=1)
plt.contour(gx, gy, truth.astype(float), [0.5], colors="red", linewidths=0.8)
plt.plot(path.points_xy[:, 0], path.points_xy[:, 1], "y-", lw=2); plt.plot(*goal, "ys")
plt.title("costmap: grown obstacles (orange), truth (red), A* path");
world.close()
""",
    ),
    (
        "md",
        r"""**Exercise.** Set `unknown_cost` to `math.inf` (`nav.costmap.inflated(nav.radius, unknown_cost=math.inf)`)
and plan again: what happens, and why does the navigator plan through unknown space by default?

## The whole search

The agent runs the paper's loop (its Fig. 4):

```
loop until found or out of time:
    if the map has no clear peak: global search (12 views, the colour peaks update M_p)
    cell = the most probable cell of M_p
    drive near it, facing it (costmap + A*, replanning as new obstacles are seen)
    local search: 9 head poses, SIFT + pose EKF     -> found: the object's 6D pose, done
    not found: Eqs. (1)-(3) with y = 0 and the local search's alpha, beta; a snapshot of M_p
```

`run_search` builds the world, places the object, runs the agent with the stereo navigator, and only
afterwards scores the result against the simulator's truth (the agent never sees it).""",
    ),
    (
        "code",
        """\
from lab.search import run_search, searchable_objects
from lab.search.navigation import navigator_factory

target = "toy_block" if FAST else "cereal_box"       # the toy block stands near the start: a short run
navigators = []

def navigate(robot, spec):                           # the stereo navigator; we keep it for its costmap
    nav_fn = navigator_factory(robot, spec)
    navigators.append(nav_fn.navigator)
    return nav_fn

print("searchable:", searchable_objects(scene))
res = run_search(target, seed=0, place=scene.body(target).pose, navigate=navigate, max_time=150 if FAST else 400)
summary = {k: v for k, v in res.to_json().items() if k not in ("events", "map_snapshots", "true_pose", "estimated_pose")}
print(summary)
for e in res.events:
    print(f"  t = {e.t:6.1f} s  {e.kind:14s} {e.detail}")
assert res.found and res.success and res.collisions == 0, res.reason
assert res.position_error_m <= 0.05 and res.orientation_error_deg <= 10
""",
    ),
    (
        "code",
        """\
from lab.search.figures import fig2_global_search, fig5_trial, fig6_snapshots

agent = res.trace.agent
for snap in agent.snapshots:
    print(f"t = {snap.t:5.1f} s  {snap.label:20s} cell {snap.cell}  max P = {snap.P.max():.3f}")
display(fig2_global_search(agent.globals_[0], res.trace.spec, search_database(target)))
nav_run = navigators[0]
display(fig5_trial(res, nav_run.costmap.state, nav_run.spec))
""",
    ),
    (
        "md",
        r"""The paper's Fig. 6 is a *failed* search: its glossy penguin cup has almost no texture, so every
local search misses it, and the snapshots show the Bayes update moving the mass from peak to peak.
Our `glossy_cup` does the same (in full mode only: it takes a few minutes).""",
    ),
    (
        "code",
        """\
if not FAST:
    cup = run_search("glossy_cup", seed=1, navigate=navigator_factory, max_time=150)
    print(cup.found, cup.reason, cup.local_searches, "local searches")
    assert not cup.found
    display(fig6_snapshots(cup))
else:
    display(fig6_snapshots(res))
""",
    ),
    (
        "md",
        r"""**Exercise.**

1. Search for the `book` on the shelf (1.2 m high). Which tilt of the global scan sees it?
2. Give the local search a larger $\beta$ (`AgentConfig(local_search=LocalSearchConfig(beta=0.5))`,
   passed as `config=` to `run_search`) and search for the glossy cup again: how does the sequence of
   snapshots change?""",
    ),
]


NB04 = [
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
    ("code", SETUP),
    (
        "md",
        r"""## Connect

A TOML file describes the robot: serial ports, speed limits, the PTU's directions and zero offsets, the
camera and its calibration file. The emulated robot is the same file with the emulators' ports.

The emulated camera here replays one stereo pair that the simulator rendered: the robot 1 m in front of
box model `M1` (the boxes of notebooks 01 and 02). The head and the base move; that picture does not.""",
    ),
    (
        "code",
        """\
from pathlib import Path
from lab.geometry import Pose2D
from lab.hardware import HardwareRobot, ReplayStereoSource, load_config, start_emulators
from lab.sim import SimRobot, SimWorld, load_box_models

REPO = Path.cwd().parent                          # the notebooks run in notebooks/
CONFIG = os.environ.get("LAB_ROBOT_CONFIG")       # e.g. hardware/robot.toml; unset: the emulators
EMULATED = CONFIG is None

# the simulated robot, for the side-by-side cells (and the picture the emulated camera replays)
world = SimWorld("box_database")
world.add_carrier(load_box_models()[1], Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi)   # M1, unique face to -x
sim = SimRobot(world, start=Pose2D(-1.0, 0.05, 0.0), seed=0)
sim.enable(); sim.command_pan_tilt(0.0, math.radians(-12)); sim.wait_pan_tilt()
sim_frame = sim.capture_stereo()
sim.disable()

if EMULATED:
    emulators = start_emulators()                 # a PTU-D46 and a Create 2 on pseudo-terminals
    cfg = load_config(REPO / "hardware" / "emulated.toml").with_ports(
        base=emulators.base_port, ptu=emulators.ptu_port)
    camera = ReplayStereoSource([(sim_frame.left, sim_frame.right)])
    print("emulators on", emulators.ports)
else:
    emulators, camera = None, None                # the camera the config describes
    cfg = load_config(Path(CONFIG) if Path(CONFIG).is_absolute() else REPO / CONFIG)
hw = HardwareRobot(cfg, camera_source=camera)
robots = {"simulator": sim, "hardware": hw}
print(f"hardware robot: {hw.state}; PTU limits read from the unit: {hw.pan_tilt_limits}")
assert hw.camera == sim.camera or not EMULATED    # the emulated robot carries the simulator's camera
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
        msg = expect(SafetyStop, lambda: [robot.step(0.02) for _ in range(50)])
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
from lab.vision import Matcher, get_database, stereo_features

db = get_database("M1")
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
counts = {}
for a, (name, robot) in zip(ax, robots.items()):
    frame = sim_frame if name == "simulator" else robot.capture_stereo()
    f = stereo_features(frame.left, frame.right, frame.camera)
    m = Matcher(db).match(f)
    counts[name] = (len(f), len(m.pairs(f, db)[0]))
    a.imshow(frame.left); a.axis("off")
    a.plot(f.uv[:, 0], f.uv[:, 1], "y.", ms=3)
    a.set_title(f"{name}: {counts[name][0]} features, {counts[name][1]} matched to M1")
print(counts)
if EMULATED:   # the replayed pair went through the hardware's rectification unchanged
    assert counts["hardware"] == counts["simulator"] and counts["hardware"][1] >= 10
""",
    ),
    (
        "code",
        """\
print(hw.read_state().counters)                  # what the drivers counted: frames, commands, retries ...
hw.close(); sim.close(); world.close()
if emulators is not None:
    emulators.close()
""",
    ),
    (
        "md",
        r"""## Exercise

1. Call `drive_for(hw, 0.2, 0.0, 2.0, dt=0.6)`: the command is re-sent every 0.6 s, just longer than the
   watchdog's 0.5 s. Plot the odometry: what do you see, and what would a real robot do?
2. With the emulators, make the pan-tilt unit stall (`emulators.ptu.stall = True`) and call `look(hw, 0.5, 0.0)`.
   What is raised, and after how long? Where is that time set?
3. The identification agent of notebook 02 uses only the `Robot` interface. What would it need to run
   on the emulated robot, and what does it see through a camera that replays one picture?""",
    ),
]


def write(name: str, cells) -> Path:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [
        nbformat.v4.new_markdown_cell(t) if k == "md" else nbformat.v4.new_code_cell(t) for k, t in cells
    ]
    for n, cell in enumerate(nb.cells):  # stable ids: rewriting a notebook changes only what changed
        cell["id"] = f"cell-{n:02d}"
    path = HERE / name
    nbformat.write(nb, path)
    return path


NOTEBOOKS = {
    "00_simulator_and_stereo.ipynb": NB00,
    "01_pose_ekf.ipynb": NB01,
    "03_grid_search.ipynb": NB03,
    "04_real_robot.ipynb": NB04,
}

if __name__ == "__main__":
    for name, cells in NOTEBOOKS.items():
        print(write(name, cells))
