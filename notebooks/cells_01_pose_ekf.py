"""Notebook 01: the pose EKF.

``make_notebooks.py`` writes these cells as ``01_pose_ekf.ipynb``: ``INTRO``, then its common set-up
cell, then ``CELLS``.
"""

INTRO = [
    (
        "md",
        r"""# 01 The pose EKF

Both papers estimate an object's 6-DOF pose with an extended Kalman filter. The state is the object's
pose in the camera frame, $X = [x, y, z, \alpha, \beta, \gamma]$ (translation, then z-y-x Euler angles).
A measured 3D feature $d_j$ matched to database feature $b_{J(j)}$ (known in the object frame) is
predicted by the **measurement model**, Eq. (3) of the identification paper:

$$d_j = x_r + R(x_o)\, b_{J(j)} + \xi, \qquad R(x_o) = R_z(\alpha) R_y(\beta) R_x(\gamma).$$""",
    ),
    (
        "md",
        r"""**Learning objectives.** After this notebook you can:

1. write the z-y-x Euler rotation $R(x_o) = R_z(\alpha) R_y(\beta) R_x(\gamma)$ and the measurement model of Eq. (3);
2. derive the measurement Jacobian $C = \partial H / \partial X$ and verify it with finite differences;
3. carry out one EKF update (innovation, $S$, gain, posterior in Joseph form) and compare it with filterpy;
4. test the filter's consistency on rendered frames with the NEES and the NIS against their chi-square bands, and see a wrong model diverge and the gate reject;
5. explain why the robot's filter uses the rotation-vector chart (gimbal lock).

**Prerequisites:** notebook [00](00_simulator_and_stereo.ipynb) (stereo points and their covariances); rotation matrices; partial derivatives; the Gaussian distribution and the idea of a Kalman filter (predict, then correct).

**Time:** about 90 minutes (reading 35, exercises 40, the episode and its widgets 15). The exercises marked *checked* answer back when you run their cell: "correct", or a hint
that names your mistake (`lab.exercises`); until you write your code they say "not attempted yet". This
notebook prepares the [`ekf` assignment](../assignments/ekf/README.md); the course plan is
[docs/course.md](../docs/course.md).""",
    ),
]

SUMMARY = [
    (
        "md",
        r"""## Summary

* The state is the object's pose in $C$, $X = [x, y, z, \alpha, \beta, \gamma]$; a matched feature is predicted by $d_j = x_r + R(x_o) b_j$ (Eq. (3)).
* The EKF linearises it with $C = [I_3 \;\; \partial(R b_j)/\partial x_o]$ per feature; a Jacobian is right when it agrees with finite differences.
* One update: $y = D - H(\bar\mu)$, $S = C\bar\Sigma C^T + \Sigma_m$, $K = \bar\Sigma C^T S^{-1}$, $\mu = \bar\mu + K y$, and the Joseph form keeps $\Sigma$ symmetric positive definite; filterpy agrees to $10^{-9}$.
* On rendered frames the filter, started by RANSAC, converges to within 2 cm of the true pose; its update by hand equals the library's and filterpy's.
* Its NIS lies in the chi-square band, its NEES above it: errors that repeat in every frame (calibration, the render) are not in the model; a wrong model drives the NIS out of its band, the gate rejects and the filter restarts.

**Next:** [02 Entropy planning](02_entropy_planning.ipynb). **Assignment:** [`ekf`](../assignments/ekf/README.md) (its
README says what to write and how it is graded).""",
    ),
]

CELLS = [
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
        r"""**Exercise 1 (checked): the rotation of Eq. (3).** Write `my_rotation_zyx(alpha, beta, gamma)`, the (3, 3) matrix $R = R_z(\alpha) R_y(\beta) R_x(\gamma)$, angles in radians. The check compares with SciPy's `Rotation.from_euler`. (It is `rotation_zyx` of the `ekf` assignment.)""",
    ),
    (
        "code",
        """\
from lab.exercises import check_rotation_zyx

def my_rotation_zyx(alpha, beta, gamma):
    raise NotImplementedError   # your code: build Rz, Ry, Rx and multiply them

check_rotation_zyx(my_rotation_zyx)
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
        r"""**Exercise 2 (checked): the Jacobian.** Write `my_measurement_jacobian(X, b_O)`, shape (3n, 6), rows $3j..3j+2$ for feature $j$, analytically (with $\partial R / \partial \alpha$ etc.; not by finite differences, the check uses those). A wrong column is named, and so is a wrong sign.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_measurement_jacobian

def my_measurement_jacobian(X, b_O):
    X, b_O = np.asarray(X, float), np.asarray(b_O, float)
    raise NotImplementedError   # your code: stack one 3 x 6 block [I_3, d(R b_j)/d(alpha, beta, gamma)] per feature

check_measurement_jacobian(my_measurement_jacobian)
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
        r"""**Exercise 3 (checked): one Kalman update.** Write `my_kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m)` returning `(mu, Sigma)`: the gain from $S$, the mean, and the covariance in Joseph form; `y` is the innovation $D - H(\bar\mu)$. The check compares with the *information form* of the same update ($\Sigma^{-1} = \bar\Sigma^{-1} + C^T \Sigma_m^{-1} C$), an independent route.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_kalman_update

def my_kalman_update(mu_bar, Sigma_bar, y, C, Sigma_m):
    raise NotImplementedError   # your code: S, K, then (mu, Sigma)

check_kalman_update(my_kalman_update)
""",
    ),
    (
        "md",
        r"""## One update in full, on rendered frames

Now the same equations on real features. The robot stands 1.1 m from box $M_0$, whose unique face is
turned 23 degrees away, under the **`sensors`** sensing profile (`realistic`'s sensors in an exact room,
notebook 00): a new noise draw in every capture, and the calibration errors of a real camera. We record an episode once (the stereo features
matched to the box's database, and the simulator's true pose for checking), then run filters on the
recording as often as we like.

The filter works in the **rotation-vector chart**: its mean is a translation $t$ and a rotation matrix
$R$, its covariance is over $[\delta t, \phi]$ with $R_{true} = \mathrm{Exp}(\phi) R$, so its Jacobian per
feature is $C_j = [\,I_3 \;\; -[R b_j]_\times]$ with no Euler angles to lock. We take the library's filter
up to the third frame, then do that frame's update by hand on the matches its gate kept, and compare
with the library and with filterpy.""",
    ),
    (
        "code",
        """\
from scipy.linalg import block_diag
from scipy.spatial.transform import Rotation
from lab.geometry import euler_zyx_to_R

N_FRAMES = 8 if FAST else 20
with SimWorld("box_database") as w:
    box = w.add_carrier(model, Pose2D(0.0, 0.0, 0.0), box_yaw=math.pi - 0.4)
    rob = SimRobot(w, start=Pose2D(-1.1, 0.1, 0.0), seed=3, sensing="sensors"); rob.enable()
    rob.command_pan_tilt(-0.09, math.radians(-11)); rob.wait_pan_tilt()
    recording = []                                    # per frame: G_RC and the matched (d_C, b_O, Sigma_d)
    for _ in range(N_FRAMES):
        fr = rob.capture_stereo()
        feats = stereo_features(fr.left, fr.right, fr.camera)
        recording.append((fr.G_RC, matcher.match(feats).pairs(feats, db)))
        rob.step(0.1)
    G_CO_true = se3_inv(w.truth.G_WC()) @ box.G_WO    # ground truth: for checking only
print("matches per frame:", [len(p[0]) for _, p in recording])

def skew(q):
    return np.array([[0, -q[2], q[1]], [q[2], 0, -q[0]], [-q[1], q[0], 0]])

lib = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(1))
for k, (G_RC, pairs) in enumerate(recording[:3]):
    lib.predict(G_RC, G_RC, np.eye(4), 0.1)
    prior = lib.estimate                              # the prediction: mu_bar and Sigma_bar
    res = lib.update(*pairs)
post = lib.estimate
d_C, b_O, Sigma_d = (a[res.inliers] for a in recording[2][1])   # the matches the gate kept

t_bar, R_bar, Sigma_bar = prior.mu[:3], euler_zyx_to_R(*prior.mu[3:]), prior.Sigma_rv
q = b_O @ R_bar.T                                     # the database features rotated into C
y = (d_C - (t_bar + q)).ravel()                       # the features' innovation, D - H(mu_bar)
C = np.vstack([np.hstack([np.eye(3), -skew(q_j)]) for q_j in q])      # (3n, 6)
Sigma_m = block_diag(*Sigma_d)                        # the features' stereo covariances (notebook 00)
S = C @ Sigma_bar @ C.T + Sigma_m                     # the innovation's covariance
K = Sigma_bar @ C.T @ np.linalg.inv(S)                # the gain, (6, 3n)
dx = K @ y                                            # the correction [dt, phi]
t_post, R_post = t_bar + dx[:3], Rotation.from_rotvec(dx[3:]).as_matrix() @ R_bar
IKC = np.eye(6) - K @ C
Sigma_post = IKC @ Sigma_bar @ IKC.T + K @ Sigma_m @ K.T              # Joseph form
nis = y @ np.linalg.solve(S, y)
print(f"{len(d_C)} of {len(recording[2][1][0])} matches kept; y: {y.size} numbers, RMS {1e3 * np.sqrt(np.mean(y**2)):.1f} mm; "
      f"S {S.shape}; K {K.shape}; NIS {nis:.1f} for {y.size} degrees of freedom")
print(f"correction: {1e3 * np.linalg.norm(dx[:3]):.1f} mm, {math.degrees(np.linalg.norm(dx[3:])):.2f} deg; "
      f"position sigma {1e3 * np.sqrt(np.diag(Sigma_bar)[:3]).round(4)} -> {1e3 * np.sqrt(np.diag(Sigma_post)[:3]).round(4)} mm")
assert np.allclose(t_post, post.mu[:3], atol=1e-12) and np.allclose(R_post, euler_zyx_to_R(*post.mu[3:]), atol=1e-12)
assert np.allclose(Sigma_post, post.Sigma_rv, atol=1e-15)          # by hand = the library

fp = ExtendedKalmanFilter(dim_x=6, dim_z=y.size)       # filterpy, on the error state [dt, phi] (prior 0)
fp.x, fp.P, fp.R = np.zeros(6), Sigma_bar.copy(), Sigma_m
fp.update(y, lambda e: C, lambda e: C @ e)
assert np.allclose(fp.x, dx, atol=1e-12) and np.allclose(fp.P, Sigma_post, atol=1e-15)   # = filterpy
print("by hand = library = filterpy")
""",
    ),
    (
        "code",
        """\
# the prior's and the posterior's 3-sigma position ellipsoids, around the true position [mm]
def ellipsoid(Sigma3, k=3.0, n=24):
    lam, W = np.linalg.eigh(Sigma3)
    a, b_ = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n // 2))
    sphere = np.stack([np.cos(a) * np.sin(b_), np.sin(a) * np.sin(b_), np.cos(b_)])
    return np.einsum("ij,jkl->ikl", W * (k * np.sqrt(lam)), sphere)

fig = plt.figure(figsize=(11, 4.5))
for i, (title, centre, Sig) in enumerate((("prior", t_bar, Sigma_bar), ("posterior", t_post, Sigma_post))):
    ax = fig.add_subplot(1, 2, i + 1, projection="3d")
    X_, Y_, Z_ = 1e3 * (ellipsoid(Sig[:3, :3]) + (centre - G_CO_true[:3, 3])[:, None, None])
    ax.plot_wireframe(X_, Y_, Z_, color="tab:blue" if i == 0 else "tab:green", lw=0.4)
    ax.scatter([0], [0], [0], color="r", s=30, label="truth")
    ax.set_xlabel("x [mm]"); ax.set_ylabel("y [mm]"); ax.set_zlabel("z [mm]"); ax.set_title(f"{title}: 3-sigma ellipsoid")
    ax.legend(fontsize=8)
plt.tight_layout()
""",
    ),
    (
        "md",
        r"""## The update in 3D

The same update in the recorded 3D view (`lab.viz.view3d`, the page `lab identify --view3d` writes):
the camera where the robot believes it is (it stands still at its start), the box at its true pose
(grey wireframe, for checking), the matches the gate kept (green), and the 3-sigma ellipsoid of the
box's position before the update (blue: the prediction) and after it (green). Play it or drag the
time slider: the ellipsoid shrinks to the update's, mostly along the line of sight, where stereo is
weakest. Scroll to zoom in on the box: the ellipsoids are millimetres to centimetres across.""",
    ),
    (
        "code",
        """\
from pathlib import Path
from lab.errors import ConfigError
from lab.viz.view3d import Node, View3D, ellipsoid_mesh, frustum_node, show_page

try:
    v3 = View3D()
except ConfigError as e:                              # the optional viewer is missing: the line says how to get it
    print(e)
else:
    G_WC = Pose2D(-1.1, 0.1, 0.0).G() @ recording[2][0]   # the robot's start and the head's pose at the update
    R_WC = G_WC[:3, :3]

    def to_W(p_C):                                    # points in C, placed in W
        return np.asarray(p_C) @ R_WC.T + G_WC[:3, 3]

    G_WO_true = G_WC @ G_CO_true
    scene3d = {
        "/camera": frustum_node(G_WC, fr.camera, scale=0.25),
        "/box/truth": Node("box", {"G_W": G_WO_true, "size": tuple(float(v) for v in db.extent),
                                   "color": (90, 90, 90), "opacity": 1.0, "wireframe": True}),
        "/features": Node("points", {"points": to_W(d_C), "colors": np.tile(np.uint8([0, 200, 0]), (len(d_C), 1)),
                                     "size": 0.008}),
    }
    axes = []
    for t3, label, centre, Sig, rgb in ((0.0, "prediction", t_bar, Sigma_bar, (31, 119, 180)),
                                        (1.0, "after the update", t_post, Sigma_post, (44, 160, 44))):
        ell = ellipsoid_mesh(to_W(centre), R_WC @ Sig[:3, :3] @ R_WC.T)   # the position's covariance, turned into W
        axes.append(ell.props["axes"])
        v3.add_step(t3, label, scene3d | {
            "/estimate/ellipsoid": Node("mesh", ell.props | {"color": rgb, "opacity": 0.5}),
            "/estimate/label": Node("label", {"text": f"{label}: 3-sigma position", "position": to_W(centre) + (0, 0, 0.15)}),
        })
    v3.camera = (tuple(G_WO_true[:3, 3] + (-0.3, -0.35, 0.2)), tuple(G_WO_true[:3, 3]))
    page = v3.save(Path("out") / "ekf_update_3d.html")
    print(f"3-sigma semi-axes [mm]: prediction {np.sort(1e3 * axes[0]).round(1)}, after {np.sort(1e3 * axes[1]).round(1)}")
    assert np.all(np.sort(axes[1]) <= np.sort(axes[0]) + 1e-12)      # an update never grows the ellipsoid
    display(show_page(page))
""",
    ),
    (
        "md",
        r"""## Over an episode: NEES and NIS against their chi-square bands

A filter is **consistent** when its errors are as large as its covariance says. Two tests:

* the **NEES** (normalised estimation error squared) $\epsilon_k = e_k^T \Sigma_k^{-1} e_k$, with $e_k$ the
  error against the truth ($[t - t_{true}, \mathrm{Log}(R_{true} R^T)]$): for a consistent filter it is
  $\chi^2$ with 6 degrees of freedom, inside $[1.24, 14.45]$ 95 % of the time;
* the **NIS** $y^T S^{-1} y$, which needs no truth: $\chi^2$ with as many degrees of freedom as $y$ has numbers.

Move the sliders: the measurement noise the filter assumes (a factor on every $\Sigma_{d_j}$), the number of
matches it may use per frame, and a **wrong model**: the database's box scaled up, as if the robot had the
wrong box's dimensions. Watch the NIS leave its band, the gate reject matches (the used count drops), and
the filter restart (`REINITIALIZED`) or skip frames: that is how the filter notices a divergence.

Look at the NEES with the *right* model: it lies far above its band, while the NIS is inside. The NIS
checks each frame against its own noise; the NEES checks the estimate against the truth, and the errors
that repeat in every frame of a robot standing still (the camera's calibration, the render) are not in
the model: averaging more frames cannot remove them, yet the filter's covariance shrinks with every
frame. Notebook 02's evidence weight $\kappa$ answers the same fact.""",
    ),
    (
        "code",
        """\
import ipywidgets as widgets
from scipy.stats import chi2

def episode(noise_scale=1.0, n_features=None, model_scale=1.0):
    # the library's filter on the recording: NEES, NIS per degree of freedom, matches used, outcome, error
    f = PoseEKF(EKFConfig(chart=OrientationChart.ROTATION_VECTOR), rng=np.random.default_rng(1))
    pick = np.random.default_rng(0)
    rows = []
    for G_RC, (d_, b_, S_) in recording:
        if n_features is not None and n_features < len(d_):
            idx = pick.choice(len(d_), n_features, replace=False)
            d_, b_, S_ = d_[idx], b_[idx], S_[idx]
        f.predict(G_RC, G_RC, np.eye(4), 0.1)
        r = f.update(d_, model_scale * b_, noise_scale**2 * S_)
        est = f.estimate
        if est is None:
            rows.append((np.nan, np.nan, r.n_used, r.outcome.name, np.nan)); continue
        R_est = euler_zyx_to_R(*est.mu[3:])
        e = np.r_[est.mu[:3] - G_CO_true[:3, 3], Rotation.from_matrix(G_CO_true[:3, :3] @ R_est.T).as_rotvec()]
        nis_dof = r.nis / r.dof if r.nis is not None and r.dof else np.nan
        rows.append((e @ np.linalg.solve(est.Sigma_rv, e), nis_dof, r.n_used, r.outcome.name, np.linalg.norm(e[:3])))
    nees, nis_dof, used, outcome, err = zip(*rows)
    return dict(nees=np.array(nees), nis_dof=np.array(nis_dof), used=np.array(used), outcome=list(outcome), err=np.array(err))

def show_episode(ep, title=""):
    fig, ax = plt.subplots(1, 3, figsize=(14, 3.2))
    k = np.arange(1, len(ep["nees"]) + 1)
    ax[0].semilogy(k, ep["nees"], "o-"); ax[0].axhspan(*chi2.ppf([0.025, 0.975], 6), color="g", alpha=0.2)
    ax[0].set_title("NEES and its 95 % band (6 dof)"); ax[0].set_xlabel("frame")
    dof = 3 * max(int(np.median(ep["used"])), 1)
    ax[1].plot(k, ep["nis_dof"], "o-"); ax[1].axhspan(*(chi2.ppf([0.025, 0.975], dof) / dof), color="g", alpha=0.2)
    ax[1].set_title(f"NIS / dof and its band ({dof} dof)"); ax[1].set_xlabel("frame")
    ax[2].plot(k, 1e3 * ep["err"], "o-", label="position error [mm]"); ax[2].plot(k, ep["used"], "s--", label="matches used")
    for kk, o in zip(k, ep["outcome"]):
        if o not in ("UPDATED", "INITIALIZED"):
            ax[2].annotate(o.lower(), (kk, 0), fontsize=7, rotation=90)
    ax[2].legend(fontsize=8); ax[2].set_xlabel("frame")
    fig.suptitle(title, fontsize=9); plt.show()

out = widgets.Output()
noise_w = widgets.FloatLogSlider(value=1.0, base=2, min=-2, max=2, step=0.25, description="noise x")
feat_w = widgets.IntSlider(value=40, min=3, max=40, description="matches")
model_w = widgets.FloatSlider(value=0.0, min=0.0, max=30.0, step=2.5, description="model +%")

def update_view(change=None):
    with out:
        out.clear_output(wait=True)
        ep = episode(noise_w.value, feat_w.value if feat_w.value < 40 else None, 1 + model_w.value / 100)
        show_episode(ep, f"noise x{noise_w.value:.2f}, at most {feat_w.value} matches, model {model_w.value:+.1f} %")

for w_ in (noise_w, feat_w, model_w):
    w_.observe(update_view, names="value")
update_view()
widgets.VBox([widgets.HBox([noise_w, feat_w, model_w]), out])
""",
    ),
    (
        "code",
        """\
right, wrong = episode(), episode(model_scale=1.3)
print(f"right model: final error {1e3 * right['err'][-1]:.1f} mm, median NIS/dof {np.nanmedian(right['nis_dof']):.2f}, "
      f"median NEES {np.nanmedian(right['nees']):.0f}, {right['used'].mean():.0f} matches used per frame")
print(f"model 30 % too large: final error {1e3 * wrong['err'][-1]:.1f} mm, median NIS/dof {np.nanmedian(wrong['nis_dof']):.2f}, "
      f"{wrong['used'].mean():.0f} matches used per frame, outcomes {sorted(set(wrong['outcome']))}")
assert right["err"][-1] < 0.02 and 0.5 < np.nanmedian(right["nis_dof"]) < 1.5      # the NIS is in its band
assert np.nanmedian(wrong["nis_dof"]) > 3 and wrong["err"][-1] > 5 * right["err"][-1]   # the wrong model: NIS out of its band
assert wrong["used"].mean() < right["used"].mean() and "REINITIALIZED" in wrong["outcome"]   # the gate rejects, the filter restarts
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
