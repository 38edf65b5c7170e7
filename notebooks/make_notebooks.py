"""Write the notebooks from their cells here, without outputs (run from the repository root).

    python notebooks/make_notebooks.py

Each notebook is a list of ("md" | "code", text) cells. Keeping the source here makes diffs readable and
guarantees the committed notebooks carry no outputs; the tests execute them headless with LAB_FAST=1.
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from cells_00_sensing import CELLS as NB00_SENSING  # notebooks/ is the script's folder: sys.path[0]
from cells_05_localization import CELLS as NB05_CELLS
from cells_05_localization import INTRO as NB05_INTRO

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
    *NB00_SENSING,
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
from lab.vision import Matcher, stereo_features
from lab.training import get_database

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


NB02 = [
    (
        "md",
        r"""# 02 Entropy planning

The identification paper (*Dynamic Sensor Planning with Stereo for Model Identification on a Mobile
Platform*) asks: which of $L$ known objects is in front of the robot? Its database holds $L = 4$ boxes,
$M_0, \dots, M_3$, of the same size. Three faces of every box carry the *same* picture; only the fourth
face differs. From a shared face no view can tell the boxes apart: the robot must see the unique face,
and the box sits on a second robot whose operator tries to keep that face hidden.

The paper's answer, built up in this notebook:

1. keep a **probability** for every model, updated by Bayes' rule with each stereo frame;
2. measure what is still unknown by the **entropy** of those probabilities;
3. for each place the robot could drive to, compute the entropy it **expects** after looking from
   there, by Monte Carlo or with precomputed **lookup tables**, and drive to the place where it
   expects to learn most.

**Notation.** Model $M_i$ is its database $\mathbf{B}_i$: 3D SIFT features $\mathbf{b}^i_l$ (points in the
object frame $O$ with their descriptors), learnt from a ring of training views. At step $k$ the robot
measures $\mathbf{D}_k = [\mathbf{d}_0 \dots \mathbf{d}_{n_k}]$, the frame's 3D SIFT features in the camera frame
$C$ (notebook 00). If $M_i$ is the object, its pose in $C$ is $\mathbf{X}_{k,i}$ (translation and z-y-x
Euler angles); one EKF per model tracks it (notebook 01), with prediction $\bar\mu_{k,i}$, $\bar\Sigma_{k,i}$.
$\mathbf{u}$ is a control action: where the robot drives next.""",
    ),
    ("code", SETUP),
    (
        "md",
        r"""## Entropy, Eq. (5)

How undecided is the robot? The entropy of the model probabilities, in nats:

$$H(M \mid \mathbf{D}_{1:k}) = -\sum_i P(M_i \mid \mathbf{D}_{1:k}) \log P(M_i \mid \mathbf{D}_{1:k}) \qquad (5)$$

It is 0 when one model is certain and $\log L$ (1.39 nats for 4 models) when all are equally likely.""",
    ),
    (
        "code",
        """\
from lab.identification import entropy

for P in ([0.25, 0.25, 0.25, 0.25], [0.7, 0.1, 0.1, 0.1], [0.997, 0.001, 0.001, 0.001]):
    P = np.array(P)
    H_by_hand = -np.sum(P * np.log(P))                        # Eq. (5)
    assert np.isclose(entropy(P), H_by_hand)
    print(f"P = {P}: H = {H_by_hand:.3f} nats")
assert np.isclose(entropy(np.full(4, 0.25)), math.log(4)) and entropy([1.0, 0, 0, 0]) == 0.0

p = np.linspace(0.25, 1.0, 100)
plt.figure(figsize=(5, 3))
plt.plot(p, entropy(np.stack([p, *(3 * [(1 - p) / 3])], axis=1)))
plt.xlabel("P(M_0), the other three equal"); plt.ylabel("H [nats]");
""",
    ),
    (
        "md",
        r"""## Model probabilities, Eqs. (7)-(9)

Bayes' rule over the models, with the previous probabilities as the prior:

$$P(M_i \mid \mathbf{D}_{1:k}) = \frac{p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i)\; P(M_i \mid \mathbf{D}_{1:k-1})}
{\sum_j p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_j)\; P(M_j \mid \mathbf{D}_{1:k-1})} \qquad (7)$$

The **data likelihood** averages over where the object may be, given model $M_i$:

$$p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i) = \int p(\mathbf{D}_k \mid \mathbf{X}_{k,i}, M_i)\;
p(\mathbf{X}_{k,i} \mid \mathbf{D}_{1:k-1}, M_i)\, d\mathbf{X}_{k,i} \qquad (8)$$

The first factor is the measurement model of notebook 01, $\mathbf{D}_k = \mathbf{H}(\mathbf{X}_{k,i}) + \xi$ with
noise covariance $\Sigma_m$; the second is the EKF's prediction $\mathcal{N}(\bar\mu_{k,i}, \bar\Sigma_{k,i})$.
Linearising $\mathbf{H}$ with its Jacobian $C_{k,i} = \partial \mathbf{H} / \partial \mathbf{X}$ turns the integral
into one Gaussian:

$$p(\mathbf{D}_k \mid \mathbf{D}_{1:k-1}, M_i) = \mathcal{N}\left(\mathbf{D}_k;\ \mathbf{H}(\bar\mu_{k,i}),\
C_{k,i} \bar\Sigma_{k,i} C_{k,i}^T + \Sigma_m\right) \qquad (9)$$

Three practical points, which the library's `ModelScorer` documents in full:

* **Which features a model explains.** A measured feature counts for $M_i$ when a database feature
  has a similar SIFT descriptor *and* lies where $\bar\mu_{k,i}$ puts it (a gate on the Mahalanobis
  distance). Eq. (9) is evaluated feature by feature over those, and every other feature gets a
  constant **clutter** density $c$, so that models which explain different numbers of features are
  compared on the same $\mathbf{D}_k$.
* **Evidence weight.** The features of one frame are not independent (one render, one pose error), so
  each frame's log-likelihood is multiplied by $\kappa = 0.008$: $P(M_i \mid \mathbf{D}_{1:k}) \propto
  p(\mathbf{D}_k \mid \cdot, M_i)^\kappa P(M_i \mid \mathbf{D}_{1:k-1})$.
* **Floor.** No probability drops below $10^{-3}$, so a model knocked out by one bad frame can come back.

We render frames of box $M_2$ from 1 m: once facing its unique face, once a shared face.""",
    ),
    (
        "code",
        """\
from lab.estimation import EKFBank, EKFConfig, OrientationChart
from lab.geometry import Pose2D
from lab.identification import ModelScorer, ScoringConfig, observe_frame, uniform
from lab.robot import StereoCamera
from lab.sim import SimRobot, SimWorld, load_box_models
from lab.vision import Matcher, stereo_features
from lab.training import get_database

models = load_box_models()                                  # M0 .. M3 (the paper's Fig. 4)
names = tuple(m.name for m in models)
dbs = [get_database(n) for n in names]                      # trained once, cached
matchers = [Matcher(db) for db in dbs]                      # the EKFs' correspondences
scoring = ScoringConfig().for_camera(StereoCamera.from_fov(320, 240, 60.0, 0.12))   # log c: the robot's camera
scorers = [ModelScorer(db, scoring) for db in dbs]          # Eqs. (7)-(9)

def look_at_box(k, box_yaw, n_frames=3):
    \"\"\"P after each of n_frames frames of box M_k turned by box_yaw [rad], seen from 1 m.\"\"\"
    with SimWorld("box_database") as w:
        w.add_carrier(models[k], Pose2D(0.0, 0.0, 0.0), box_yaw=box_yaw)
        robot = SimRobot(w, start=Pose2D(-1.0, 0.0, 0.0), seed=0)
        robot.enable()
        robot.command_pan_tilt(0.0, math.atan2(0.49 - 0.7, 1.0))   # box centre 0.49 m high, head 0.7 m, 1 m away
        robot.wait_pan_tilt()
        bank = EKFBank(len(dbs), EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(0))
        P, history = uniform(len(dbs)), []
        for _ in range(n_frames):
            frame = robot.capture_stereo()
            f = stereo_features(frame.left, frame.right, frame.camera, t=frame.t)
            predicted = bank.predict(frame.G_RC, frame.G_RC, np.eye(4), 0.1)   # the robot stands still
            obs = observe_frame(P, f, bank, predicted, matchers, scorers)
            history.append((P, obs))
            P = obs.belief.P
            robot.step(0.1)
    return np.array([o.belief.P for _, o in history]), history, f, frame

P_unique, hist_unique, f_last, frame_last = look_at_box(2, math.pi)   # the unique face (+X) towards the robot
P_shared, _, _, _ = look_at_box(2, 0.0)                               # a shared face towards the robot
fig, ax = plt.subplots(1, 3, figsize=(13, 3))
ax[0].imshow(frame_last.left); ax[0].axis("off"); ax[0].set_title("M2, unique face")
for a, P, title in ((ax[1], P_unique, "unique face"), (ax[2], P_shared, "shared face")):
    for n, row in enumerate(P):
        a.bar(np.arange(4) + 0.25 * n - 0.25, row, width=0.25, label=f"frame {n + 1}")
    a.set_xticks(range(4), names); a.set_ylim(0, 1); a.set_title(f"P(M_i | D): {title}"); a.legend(fontsize=7)
print("unique face:", P_unique.round(3).tolist()); print("shared face:", P_shared.round(3).tolist())
print(f"entropy after 3 frames: {entropy(P_unique[-1]):.3f} (unique face), {entropy(P_shared[-1]):.3f} "
      f"(shared face), of log 4 = {math.log(4):.3f} nats")
assert P_unique[:, 2].max() >= 0.95 and P_unique[-1].argmax() == 2          # the unique face identifies M2
assert entropy(P_shared[-1]) > 0.97 * math.log(4) and P_shared.max() < 0.3  # a shared face teaches (almost) nothing
""",
    ),
    (
        "code",
        """\
from scipy.stats import multivariate_normal
from lab.estimation import measurement_jacobian_rv, measurement_model
from lab.identification import apply_floor

# Eq. (7) by hand, for the last frame of the unique face: prior times likelihood^kappa, normalised, floored
prior, obs = hist_unique[-1]
b = obs.belief
w = np.log(prior) + scoring.evidence_weight * b.log_likelihoods
P_by_hand = apply_floor(np.exp(w - w.max()) / np.exp(w - w.max()).sum(), scoring.floor)
assert np.allclose(P_by_hand, b.P)
print("features explained by each model:", dict(zip(names, b.n_explained.tolist())), "of", b.n_features)

# Eq. (9) for one feature that M2 explains: N(d; H(mu_bar, b_l), C Sigma_bar C^T + Sigma_m), against scipy
state = obs.updates[2].estimate                       # M2's pose after this frame
e = scorers[2].explain(f_last, state)
j = int(np.flatnonzero(e.explained)[0])
d, b_l = f_last.points_C[j], dbs[2].points_O[e.idx_db[j]]
C = measurement_jacobian_rv(state.mu, b_l[None]).reshape(3, 6)
S = C @ state.Sigma_rv @ C.T + f_last.covariances[j]
ref = multivariate_normal(measurement_model(state.mu, b_l[None])[0], S).logpdf(d)
print(f"feature {j}: log N = {e.log_density[j]:.3f} (library), {ref:.3f} (scipy)")
assert np.isclose(e.log_density[j], ref)
""",
    ),
    (
        "md",
        r"""**Exercise.** Set $\kappa$ to 1 (`ScoringConfig(evidence_weight=1.0)`, passed to every `ModelScorer`)
and look at the shared face again. What happens, and why is $\kappa$ needed?

## What will the next view teach? Eqs. (4), (6), (10)-(12)

The **information gain** of an action $\mathbf{u}$ is the entropy now minus the entropy expected after
the measurement $\mathbf{D}_{k+1}$ it brings, and the robot takes the best action:

$$I_{\mathbf{u}} = H(M \mid \mathbf{D}_{1:k}) - E_{\mathbf{D}_{k+1}}\left[H(M \mid \mathbf{D}_{1:k+1}, \mathbf{u})\right]
\qquad (4), \qquad \mathbf{u}^* = \arg\max_{\mathbf{u}} I_{\mathbf{u}} \qquad (6)$$

The candidate actions are goals on a **ring** 1 m around the object's estimate, every 10 degrees, the
robot facing the object. The expectation is over measurements nobody has seen yet. Monte Carlo
approximates it: assume model $M_i$ is the truth (with its probability), sample $N$ measurement sets
$\tilde{\mathbf{D}}$ that $M_i$ would produce from the goal, and compute the posterior entropy $H^+$ each
would leave, scoring $\tilde{\mathbf{D}}$ against every model $M_j$ with Eq. (9), feature by feature
(Eqs. (11)-(12)):

$$E_{\mathbf{D}_{k+1}}[H^+] \approx \sum_i P(M_i \mid \theta)\ \frac{1}{N} \sum_{n=1}^{N} H^+(\tilde{\mathbf{D}}_n),
\qquad \tilde{\mathbf{D}}_n \sim p(\mathbf{D}_{k+1} \mid \theta, \mathbf{u}, M_i) \qquad (10)$$

($\theta$: everything measured so far). The planner's picture of the object is a set of **hypotheses**
(`ModelHypotheses`): for every model, the probability $P(M_i)$ and the object's pose in the world frame
$W$ with its uncertainty, taken from that model's EKF.

To see the planning on its own, quickly and exactly, we use **synthetic** boxes: the real geometry
(three faces with one shared page, one unique face), 30 features per face, no rendering. The box's
unique face points to azimuth 60 degrees; every model's pose estimate is good (1.4 cm, 1.8 degrees).""",
    ),
    (
        "code",
        """\
import time
from lab.geometry import Rz, se3
from lab.identification import (LookupTableEvaluator, ModelHypotheses, MonteCarloConfig, MonteCarloEvaluator,
                                calc_possible_control_actions, information_gain)
from lab.identification.synthetic import synthetic_box_databases, synthetic_tables
from lab.robot import StereoCamera

camera = StereoCamera.from_fov(320, 240, 60.0, 0.12, mount_R=(0.0, 0.0, 0.7))   # the robot's camera
synth = synthetic_box_databases(4, np.random.default_rng(0))                      # S0 .. S3
G_WO = se3(Rz(math.radians(60)), [0.0, 0.0, 0.49])              # the box in W, unique face towards 60 deg
Sigma = np.diag([2e-4] * 3 + [1e-3] * 3)    # pose covariance: position [m^2], small rotation angles [rad^2]
hyp = ModelHypotheses.one_pose_each(uniform(4), np.stack([G_WO] * 4), np.stack([Sigma] * 4))
actions = calc_possible_control_actions(hyp.object_centre_W(), camera)   # calcPossibleControlActions
azimuth = np.degrees([a.azimuth for a in actions])
H_now = entropy(hyp.P)

mc = MonteCarloEvaluator(synth, camera, config=MonteCarloConfig(n_samples=16 if FAST else 64))
t0 = time.perf_counter(); EH_mc = mc.expected_entropy(actions, hyp); t_mc = time.perf_counter() - t0
gain_mc = information_gain(H_now, EH_mc)                         # Eq. (4)
best = int(np.argmax(gain_mc))                                   # Eq. (6)
print(f"H now {H_now:.3f} nats; Monte Carlo: best goal at azimuth {azimuth[best]:.0f} deg, "
      f"gain {gain_mc[best]:.2f} nats ({t_mc:.2f} s for {len(actions)} goals)")
off_deg = np.abs((azimuth - 60 + 180) % 360 - 180)               # angle between goal and unique face
faces_unique = off_deg < 55                                       # goals that see the unique face
assert faces_unique[best] and gain_mc[off_deg > 95].max() < 0.01  # shared faces only: nothing to learn
""",
    ),
    (
        "md",
        r"""## Lookup tables, Eqs. (13)-(15)

Monte Carlo samples and scores whole feature sets for every goal: too slow to repeat while the robot
moves. The paper precomputes instead, in its **Table I**: render true model $M_i$ from each training
pose $T$ times; if feature $\mathbf{b}^j_l$ of model $M_j$ is matched in $\tau$ of them, $P^j_{\mathbf{b}_l} = \tau / T$.
From a goal, the number $W_{ij}$ of features of $M_j$ that will correspond when $M_i$ is the truth is
a sum of those Bernoulli variables (looked up in the row of the nearest training pose). Then the paper
takes the residual and its covariance as the same for every feature,

$$\Sigma_{\tilde{\mathbf{d}}_m} = \Sigma_o \quad (13), \qquad \tilde{\mathbf{d}}_m - \mu_{\tilde{\mathbf{d}}_m} = \delta_o \quad (14),$$

so the likelihood of the predicted measurement under $M_j$ needs only $W_{ij}$:

$$p(\tilde{\mathbf{D}} \mid \theta, \mathbf{u}, M_j) = \left[(2\pi)^{3/2} |\Sigma_o|^{1/2}\right]^{-W_{ij}}
\exp\left(-\frac{W_{ij}}{2}\, \delta_o^T \Sigma_o^{-1} \delta_o\right) \qquad (15)$$

(each feature is 3-D, hence $3/2$), times $c^{\,n - W_{ij}}$ for the $n - W_{ij}$ measured object features
that $M_j$ does not explain, as in Eq. (9) ($n$ is at least $\max_j W_{ij}$; it cancels in Eq. (7)).
The library samples the $W_{ij}$ of one draw at *one* quantile level for all $j$, so that two models
with equal table rows (a shared face) always get equal counts, and no information appears from chance
alone. We compute Eqs. (10) and (15) by hand for one goal and compare with the library.""",
    ),
    (
        "code",
        """\
from lab.identification import eq15_log_likelihood, posterior
from lab.identification.lut import Eq15Constants
from lab.identification.viewpoints import nearest_viewpoint

tables = synthetic_tables(synth)                     # Table I of the synthetic boxes, without rendering
lut = LookupTableEvaluator(tables, camera)
# a sharper pose (a tenth of the standard deviations), so that each model looks up exactly one table row
sharp = ModelHypotheses.one_pose_each(uniform(4), np.stack([G_WO] * 4), np.stack([Sigma / 100] * 4))
a = actions[6]                                       # the goal at azimuth 60 deg, facing the unique face
G_CO, Sigma_C = sharp.relative_to(a.G_WC)            # each model's pose seen from that goal's camera
c = Eq15Constants()
EH_by_hand = 0.0
for i in range(4):                                   # assume M_i is the truth
    row = nearest_viewpoint(G_CO[i], tables.viewpoints)
    Sigma_o = c.Sigma_o(camera, np.linalg.norm(G_CO[i][:3, 3]), Sigma_C[i])                   # Eq. (13)
    delta_o = c.delta_o(Sigma_o)                                                             # Eq. (14)
    W = tables.W_quantiles[i, :, row, :].T           # (samples, L): W_ij at the stratified levels
    log_p = eq15_log_likelihood(W, Sigma_o, delta_o) + (W.max(axis=1, keepdims=True) - W) * scoring.log_clutter_density
    H_plus = entropy(posterior(np.log(sharp.P), log_p, scoring))   # Eq. (7) and Eq. (5) for every sample
    EH_by_hand += sharp.P[i] * H_plus.mean()                       # Eq. (10)
EH_lib = lut.expected_entropy([a], sharp)[0]
print(f"E[H+] at azimuth 60 deg: {EH_by_hand:.6f} (by hand), {EH_lib:.6f} (library)")
assert np.isclose(EH_by_hand, EH_lib)

t0 = time.perf_counter(); EH_lut = lut.expected_entropy(actions, hyp); t_lut = time.perf_counter() - t0
gain_lut = information_gain(H_now, EH_lut)
print(f"lookup tables: {t_lut * 1e3:.1f} ms for {len(actions)} goals, {t_mc / t_lut:.0f} x faster than Monte Carlo")
plt.figure(figsize=(7, 3))
plt.plot(azimuth, gain_mc, "o-", label="Monte Carlo, Eqs. (10)-(12)")
plt.plot(azimuth, gain_lut, "s-", label="lookup tables, Eqs. (13)-(15)")
plt.axvspan(5, 115, color="gold", alpha=0.2, label="unique face in view")
plt.xlabel("goal azimuth around the box [deg]"); plt.ylabel("information gain [nats]"); plt.legend();
assert faces_unique[int(np.argmax(gain_lut))]
assert gain_mc[int(np.argmax(gain_lut))] >= 0.9 * gain_mc.max()   # the tables choose what Monte Carlo rates highly
""",
    ),
    (
        "md",
        r"""**A real table.** `lab tables` renders every box from each of the 36 training poses 8 times (some
minutes, cached). Here we build two rows of $M_2$'s tables with 2 renders each: row 0 looks at its
unique face, row 18 at the opposite, shared face. The expected count $E[W_{2j}]$ is the sum of a row.""",
    ),
    (
        "code",
        """\
from lab.training import TableParams, build_model_tables

rows = (0, 18)
t2 = build_model_tables("M2", dbs, TableParams(repeats=2), viewpoint_indices=rows)
EW = np.array([[t2.table(j)[r].sum() for j in names] for r in rows])     # E[W_2j] at the two rows
print("Table I pose column (x, y, z [m], alpha, beta, gamma [rad]):\\n", t2.poses[list(rows)].round(2))
for r, ew in zip(rows, EW):
    print(f"row {r:2d}: E[W_2j] = {dict(zip(names, ew.round(1).tolist()))}")
assert EW[0, 2] >= 5 * max(np.delete(EW[0], 2).max(), 1.0)        # unique face: only M2 explains it
assert EW[1].min() >= 5 and EW[1].max() <= 1.5 * EW[1].min()      # shared face: every model does
""",
    ),
    (
        "md",
        r"""## The ring picture (the paper's Fig. 6)

`plan_next_best_view` chains *calcPossibleControlActions* and *calcExpectedEntropy* and applies
Eq. (6). Each candidate goal is coloured by its information gain; the star is $\mathbf{u}^*$.""",
    ),
    (
        "code",
        """\
from lab.identification import plan_next_best_view
from lab.viz.identification import fig6

plan = plan_next_best_view(hyp, camera, lut)
cands = np.array([[a.pose.x, a.pose.y, a.pose.theta] for a in plan.actions])
fig6(cands, plan.gain, plan.best, robot_xy_theta=(-1.2, 0.0, 0.0), object_xy=hyp.object_centre_W()[:2]);
assert faces_unique[plan.best]
""",
    ),
    (
        "md",
        r"""## The closed loop, against an evasive operator

`IdentificationAgent` runs the paper's loop (its Fig. 3) on any `Robot`, one stereo frame per step:

```
predict every model's EKF (robot, head and object motion); stereo features D_k; update every EKF
model probabilities, Eqs. (7)-(9), and entropy, Eq. (5)               calcCurrentEntropy
head: keep the object in the middle of the image (tracking), or scan for it
at the goal: candidate goals on the ring, expected entropy, Eq. (6)    calcExpectedEntropy
drive along the ring to the goal; stop when one model stays above 0.95 for 1 s
```

The box rides on a carrier driven by an **evasive mover**, our stand-in for the paper's operator: it
turns the box so that its unique face points away from the robot, reacting after 0.5 s and turning at
most 0.15 rad/s (the mover may look at the true poses; the agent never does). In fast mode the box
starts with its unique face half turned towards the robot (45 degrees off) and the planner is Monte Carlo
(it needs no tables): a short episode, one decision, before the operator has turned the face away; in
full mode the face starts pointing away, as in the paper, and the planner uses the lookup tables (`lab
tables` builds them on first use).

One departure from Eq. (6): once the robot has driven one way round the box, it keeps going that way
when the best goal ahead has at least half the best gain (`AgentConfig(keep_direction=0.5)`). The
gain is computed for the box as it stands, and the operator turns the face away while the robot drives:
only steady travel one way gains on the face (the robot circles at 15-17 deg/s, the box turns at 8.6),
and a reversal gives the gained angle back. Try `keep_direction=1.0` (the plain argmax) in full mode
and compare the paths in Fig. 6 and the number of actions.""",
    ),
    (
        "code",
        """\
from lab.identification.agent import AgentConfig, IdentificationAgent
from lab.sim.movers import make_mover
from lab.viz.identification import fig5
from lab.viz.live import LiveView

true_model = 2
world = SimWorld("arena")
carrier = world.add_carrier(models[true_model], Pose2D(0.0, 0.0, 0.0), box_yaw=math.radians(135 if FAST else 0))
robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=0)
robot.enable()
carrier.mover = make_mover("evasive", carrier, observer_pose=world.truth.robot_pose)
if FAST:
    planner, evaluator = "mc", MonteCarloEvaluator(dbs, robot.camera, config=MonteCarloConfig(n_samples=8))
else:
    from lab.identification import make_evaluator
    from lab.training import get_tables              # the lookup tables (built on first use: `lab tables`)

    planner = "lut"
    evaluator = make_evaluator(planner, dbs, robot.camera, tables=get_tables(names, dbs=dbs))
agent = IdentificationAgent(robot, dbs, planner=planner, seed=0, evaluator=evaluator,
                            config=AgentConfig(max_actions=8, max_time_s=60 if FAST else 240))
true_poses = []                                      # the box's true pose at every frame: for the plot only
agent.on_step = lambda agent_, frame: true_poses.append(carrier.G_WO.copy())
view = LiveView.for_identification(agent)            # the paper's Fig. 6 interface, live: ring, camera, P
display(view.widget)
identified = agent.run()
print(f"identified M{identified} (true: M{true_model}) after {robot.now():.1f} s and {agent.n_actions} actions; "
      f"P = {agent.P.round(3)}")
assert identified == true_model and view.n_draws > 0
""",
    ),
    (
        "code",
        """\
steps = agent.steps
t = np.array([s.t for s in steps])
yaw = lambda G: math.atan2(G[1, 0], G[0, 0])
est = np.array([[*s.estimates_W[true_model][:3, 3], yaw(s.estimates_W[true_model])] for s in steps])
true = np.array([[*G[:3, 3], yaw(G)] for G in true_poses])
fig5(t, est, true, np.array([s.posterior for s in steps]), [s.head_mode for s in steps],
     [d.t for d in agent.decisions], list(names), true_model)
d = agent.decisions[-1]
odom = np.array([s.odom for s in steps])
fig6(d.candidates, d.gains, d.chosen, odom[-1], d.centre_W[:2], path_xy=odom[:, :2]);
""",
    ),
    (
        "md",
        r"""## Your turn: drive the object

Now *you* are the operator. The box's carrier takes its commands from the buttons of a
`TeleopPanel` (a `TeleopMover`: each button's command holds until the next one); the robot runs the
same agent, and a `LiveView` shows what it thinks. Try to keep the unique face hidden, then give up and
show it. "run 1 s" lets 1 s of simulated time pass (5 agent steps). To drive while the agent runs on its
own, start the whole episode in a worker thread instead: `run_future = in_background(agent.run)`; the
buttons then act while it runs (`run_future.result()` waits for its end).

In fast mode the cell after the panel plays the operator: it turns the unique face, which starts to
the side, towards the robot.""",
    ),
    (
        "code",
        """\
import ipywidgets as widgets
from lab.sim.movers import MoverLimits, TeleopMover
from lab.viz.live import TeleopPanel, TeleopSpeeds, in_background

world.close()
world = SimWorld("arena")
carrier = world.add_carrier(models[true_model], Pose2D(0.0, 0.0, 0.0), box_yaw=math.radians(90))
robot = SimRobot(world, start=Pose2D(-1.2, 0.0, 0.0), seed=1)
robot.enable()
carrier.mover = TeleopMover(carrier, MoverLimits(max_box_turn_rate=0.8))    # you are the operator
panel = TeleopPanel(carrier.mover, TeleopSpeeds(box_turn_rate=0.8))
agent = IdentificationAgent(robot, dbs, planner=planner, seed=0, evaluator=evaluator,
                            config=AgentConfig(max_actions=8, max_time_s=600))
view = LiveView.for_identification(agent)

def run(seconds=1.0):
    \"\"\"Let `seconds` of simulated time pass: the agent perceives, plans and drives; the box does what you said.\"\"\"
    for _ in range(round(seconds / agent.config.dt)):
        if agent.identified is None:
            agent.step()
        else:
            robot.step(agent.config.dt)

run_button = widgets.Button(description="run 1 s", icon="play")
run_button.on_click(lambda _button: run(1.0))
run(0.2)                                             # one step, so that the view has a picture
widgets.VBox([widgets.HBox([panel.widget, run_button]), view.widget])
""",
    ),
    (
        "code",
        """\
if FAST:                                  # the operator shows the unique face: a quarter turn towards the robot
    panel.press("box left"); run(2.0)     # 0.8 rad/s for 2 s
    panel.press("stop")
    while agent.P[true_model] < 0.95 and robot.now() < 5.0:
        run(0.4)
    print(f"t = {robot.now():.1f} s: P = {agent.P.round(3)}")
    assert agent.P[true_model] >= 0.95
""",
    ),
    (
        "md",
        r"""**Exercise.**

1. Hide the unique face by turning the box as the robot drives round it. How long can you keep it
   hidden? What does the planner do when the box turns faster than the robot can drive?
2. Replace the planner by `"random"` or `"circle"` (the baselines of `lab identify`) and compare the
   number of actions until the box is identified.""",
    ),
    ("code", "world.close()\n"),
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
from lab.runs.search import map_spec
from lab.scene import load_scene

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
from lab.search import ProbabilityMap
from lab.training import search_database
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
        r"""**From a cluster to a map cell.** *Dense* stereo gives a disparity for every pixel, not only at
SIFT features (OpenCV's semi-global block matching). The cluster's disparity $d$, the median over its
most object-like pixels, gives its point $p_C$ in the camera frame by the triangulation of notebook 00,
and the world point is

$$p_W = G_{WR}\, G_{RC}\, p_C ,$$

with $G_{WR}$ the robot's pose in the world frame $W$ from odometry and $G_{RC}$ the left camera's pose
on the robot, from the pan-tilt head's current angles ($G_{AB}$ maps points from frame $B$ into frame
$A$, the papers' convention). A point at a height where an object can stand, inside the room, is a
positive detection of its cell with the growing $\beta$ above. `process_view` does this for one view;
the global search does it for 12 views (6 pans at 2 tilts) and uses the whole scan's histogram as $I$.""",
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
height $z$ above the floor. A point with $|z| \le 3$ cm is floor; one from 5 cm up to the robot's height
(plus a margin) is an obstacle: a table top at 0.75 m is one, because the head would hit it. A cell is
*obstacle* when obstacle points fell in it (obstacle wins over floor, the paper's conservative rule),
*free* when only floor points did, and *unknown* otherwise. Obstacles are then **grown** by the robot's
radius, so that A* can plan for a point.

A* searches the 8-connected grid. A step from cell $u$ into its neighbour $v$ costs
$c(u, v) = \ell(u, v)\, m(v)$, with $\ell = r$ or $\sqrt 2\, r$ ($r$ the cell size) and a multiplier
$m(v) \ge 1$: 1 on seen floor, 2 in unknown cells, more close to obstacles, $\infty$ inside grown ones.
Its heuristic, the estimate of the cost still to go from cell $n$, is the octile distance
$\hat c(n) = m_{min}\, r\, (\Delta_{max} + (\sqrt 2 - 1)\, \Delta_{min})$ ($\Delta$: the cell offsets from $n$
to the goal, $m_{min}$ the smallest multiplier). It never overestimates the remaining cost, so the path
A* returns is a cheapest one.

The robot looks around with its head tilted down, and the navigator builds the costmap:""",
    ),
    (
        "code",
        """\
from scipy.ndimage import binary_dilation
from lab.navigation import CellState, Navigator, room_bounds

nav = Navigator(robot, bounds=room_bounds(scene))   # the costmap covers the scene's floor
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
    (ours) the colours were there but no pose: the side look, 35 deg round the colour peak each way
```

Three things in the local search are ours, not the paper's: before a cell is given up, a *second look*
at the object's colour peaks near it, on a region enlarged twice (a small object far below the camera);
after a miss that saw those colours, the *side look* (a book with its 5 cm spine to the room shows no
pose from in front: 35 degrees round, a cover turns to the camera); and two checks before "found": the
pose must explain enough of the database features it predicts in view, and it must rest on one of the
box's faces within 10 degrees (a pose tilted more than that is more than 10 degrees wrong).

`run_search` builds the world, places the object, runs the agent with the stereo navigator, and only
afterwards scores the result against the simulator's truth (the agent never sees it).""",
    ),
    (
        "code",
        """\
from lab.runs.search import run_search
from lab.runs.placement import searchable_objects
from lab.runs.search import navigator_factory

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
from lab.viz.search import fig2_global_search, fig5_trial, fig6_snapshots

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

1. Search for the `book` on the shelf, 1.2 m high (`run_search("book", seed=0, place=scene.body("book").pose,
   navigate=navigator_factory)`). Which tilt of the global scan sees it?
2. Give the local search a larger $\beta$ (`from lab.search import AgentConfig, LocalSearchConfig`, then
   `config=AgentConfig(local_search=LocalSearchConfig(beta=0.5))` in `run_search`) and search for the
   glossy cup again: how does the sequence of snapshots change?

## Which cell next: the highest, or the best buy?

The paper drives to the map's maximum wherever it is. But a cell costs time: the drive there, $d_i / v$,
and the look, $t_{look}$. If looking at cell $i$ finds the object with probability $P_i$ (times the same
$1 - \beta$ everywhere) and costs $t_i$, the order that minimises the **expected time to find** visits
the cells in decreasing $P_i / t_i$: swapping two neighbours $i, j$ in any order changes the expected
time by $P_j t_i - P_i t_j$, so $i$ goes first exactly when $P_i / t_i > P_j / t_j$. With travel the
costs depend on where the robot stands, so `--strategy rate` takes this greedily, one visit at a time,
among the map's peaks (`lab.search.agent.detection_rates`). Check the claim on five cells by brute force:""",
    ),
    (
        "code",
        """\
import itertools
from lab.search.agent import detection_rates

P = np.array([0.30, 0.10, 0.25, 0.05, 0.20])                  # the peaks' probabilities
centres = np.array([[4.0, 0.0], [0.5, 0.0], [0.0, -2.0], [1.0, 1.0], [0.0, 6.0]])   # [m], robot at (0, 0)
rate = detection_rates(P, centres, (0.0, 0.0), standoff_m=0.75, speed_m_s=0.15, look_time_s=8.5)
t = P / rate                                                   # each cell's cost [s]

def expected_time(order):
    return sum(P[i] * t[list(order[: k + 1])].sum() for k, i in enumerate(order))

best = min(itertools.permutations(range(5)), key=expected_time)
by_height, by_rate = (tuple(int(i) for i in np.argsort(-v)) for v in (P, rate))
for name, order in (("highest first", by_height), ("best buy first", by_rate), ("brute force", best)):
    print(f"{name:15s} {order}  expected time {expected_time(order):6.1f} s")
assert by_rate == best
""",
    ),
    (
        "md",
        r"""**Exercise.** Run the toy-block search above with `strategy="rate"` (an argument of `run_search`).
Does it visit the cells in another order? Where the map has one clear peak the two strategies agree;
they differ when a weaker peak lies much nearer.""",
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
from lab.search.agent import AgentConfig
from lab.search.global_search import GlobalSearchConfig

config, navigate = None, navigator_factory        # the agent's and the navigator's defaults
place = (0.0, -1.6, 0.0, -90.0)                   # the cereal box 1.4 m in front of the robot's start
if FAST:
    config = AgentConfig(global_search=GlobalSearchConfig(pans_deg=(0.0,), tilts_deg=(-30.0,)))
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


NB05 = [*NB05_INTRO, ("code", SETUP), *NB05_CELLS]


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
    "02_entropy_planning.ipynb": NB02,
    "03_grid_search.ipynb": NB03,
    "04_real_robot.ipynb": NB04,
    "05_localization.ipynb": NB05,
}

if __name__ == "__main__":
    for name, cells in NOTEBOOKS.items():
        print(write(name, cells))
