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


def write(name: str, cells) -> Path:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [
        nbformat.v4.new_markdown_cell(t) if k == "md" else nbformat.v4.new_code_cell(t) for k, t in cells
    ]
    path = HERE / name
    nbformat.write(nb, path)
    return path


NOTEBOOKS = {"00_simulator_and_stereo.ipynb": NB00, "01_pose_ekf.ipynb": NB01}

if __name__ == "__main__":
    for name, cells in NOTEBOOKS.items():
        print(write(name, cells))
