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
4. run the filter on rendered stereo frames and read its error against the simulator's truth;
5. explain why the robot's filter uses the rotation-vector chart (gimbal lock).

**Prerequisites:** notebook [00](00_simulator_and_stereo.ipynb) (stereo points and their covariances); rotation matrices; partial derivatives; the Gaussian distribution and the idea of a Kalman filter (predict, then correct).

**Time:** about 75 minutes (reading 30, exercises 45). The exercises marked *checked* answer back when you run their cell: "correct", or a hint
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
* On rendered frames the filter, started by RANSAC, converges to within 2 cm of the true pose.

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
        r"""## Exercise

1. Flip the sign of one column of the Jacobian and run the finite-difference check again: what fails?
2. Why does the robot use `OrientationChart.ROTATION_VECTOR`? (Hint: what is $\beta$ when the camera
   looks straight at the box's $x$ face? Look up *gimbal lock*.)""",
    ),
]
