"""Notebook 02: entropy planning.

``make_notebooks.py`` writes these cells as ``02_entropy_planning.ipynb``: ``INTRO``, then its common set-up
cell, then ``CELLS``.
"""

INTRO = [
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
    (
        "md",
        r"""**Learning objectives.** After this notebook you can:

1. compute the entropy of the model probabilities (Eq. (5)) and state its bounds $[0, \log L]$;
2. update the model probabilities with Bayes' rule in log space (Eq. (7)), with the evidence weight and the floor;
3. compute the information gain of an action (Eqs. (4), (10)) and choose the next-best view (Eq. (6));
4. compare the Monte Carlo and the lookup-table expected entropy (Eqs. (10)-(15)) in speed and in the view they choose;
5. run the identification loop against an evasive operator, and be that operator yourself.

**Prerequisites:** notebooks [00](00_simulator_and_stereo.ipynb) and [01](01_pose_ekf.ipynb); discrete probability (Bayes' rule, expectation); logarithms.

**Time:** about 90 minutes (reading 40, exercises 30, the closed loop 20). The exercises marked *checked* answer back when you run their cell: "correct", or a hint
that names your mistake (`lab.exercises`); until you write your code they say "not attempted yet". This
notebook prepares the [`planning` assignment](../assignments/planning/README.md); the course plan is
[docs/course.md](../docs/course.md).""",
    ),
]

SUMMARY = [
    (
        "md",
        r"""## Summary

* The robot keeps one probability per model and updates it frame by frame with Eq. (7); the data likelihood of Eq. (9) is a Gaussian in the EKF's predicted features.
* Entropy (Eq. (5)) measures what is still unknown: 0 when one model is certain, $\log L$ when all are equally likely.
* The information gain of an action (Eq. (4)) is the entropy now minus the entropy expected after its measurement; Eq. (6) takes the best.
* Lookup tables (Eqs. (13)-(15)) choose what Monte Carlo rates highly, at a fraction of its cost: fast enough to plan while driving.

**Next:** [03 Grid search](03_grid_search.ipynb). **Assignment:** [`planning`](../assignments/planning/README.md) (its
README says what to write and how it is graded).""",
    ),
]

CELLS = [
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
        r"""**Exercise 1 (checked): entropy.** Write `my_entropy(P)` in nats, with $0 \log 0 = 0$ (a model with probability 0 adds nothing). The check compares with `scipy.stats.entropy`. (It is `entropy` of the `planning` assignment.)""",
    ),
    (
        "code",
        """\
from lab.exercises import check_entropy

def my_entropy(P):
    P = np.asarray(P, float)
    raise NotImplementedError   # your code: Eq. (5)

check_entropy(my_entropy)
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
        r"""**Exercise 2 (checked): Bayes' rule over the models.** Write `my_model_probabilities(P_prior, log_likelihood)`: Eq. (7) with $\kappa = 1$ and no floor. The log-likelihoods may be near $-3000$, where `np.exp` gives 0.0: work in log space. The check compares with SciPy's `softmax`. (`model_probabilities` of the `planning` assignment adds the floor.)""",
    ),
    (
        "code",
        """\
from lab.exercises import check_model_probabilities

def my_model_probabilities(P_prior, log_likelihood):
    P_prior, log_likelihood = np.asarray(P_prior, float), np.asarray(log_likelihood, float)
    raise NotImplementedError   # your code: the posterior, shape (L,), summing to 1

check_model_probabilities(my_model_probabilities)
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
        r"""**Exercise 3 (checked): the information gain.** Eq. (4) for a measurement with a few outcomes $y$ (say: "the unique face is seen" or not): given $P(M_i)$ and a table $p(y \mid M_i)$, each outcome has probability $p(y) = \sum_i P(M_i)\, p(y \mid M_i)$ and leaves the posterior $P(M_i \mid y)$ (Bayes). Write `my_information_gain(P, likelihood)`, `likelihood[i, y]` $= p(y \mid M_i)$, that returns $H(M) - \sum_y p(y)\, H(M \mid y)$ [nats]. The check computes the same number by another route (the mutual information of the joint distribution).""",
    ),
    (
        "code",
        """\
from lab.exercises import check_information_gain

def my_information_gain(P, likelihood):
    P, likelihood = np.asarray(P, float), np.asarray(likelihood, float)
    raise NotImplementedError   # your code: H now minus the expected entropy after the measurement

check_information_gain(my_information_gain)
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
from lab.errors import ConfigError
from lab.viz.identification import fig5
from lab.viz.live import LiveView
from lab.viz.view3d import View3D

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
try:                                                 # and the episode recorded in 3D (the optional viser)
    view3d, no_view3d = View3D.for_identification(agent, world=world), None
except ConfigError as e:
    view3d, no_view3d = None, str(e)                 # the line says how to get it
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
        r"""## The episode in 3D: the ring's information gain

The same episode, recorded as a 3D scene (`View3D.for_identification`; `lab identify --view3d FILE.html`
writes the same page), one step per stereo frame. At each decision the ring of candidate views appears
coloured by its expected information gain (viridis: yellow gains the most; gold is the chosen goal), the
Fig. 6 of above standing round the box. Each model's pose estimate is drawn as its box with the 3-sigma
ellipsoid of its position, coloured by the model's probability (plasma: yellow is near 1); the frame's
features are green where the most probable model's EKF used them, orange where its gate rejected them,
grey where they matched nothing; and P(M_i) and the normalised entropy run as time series on a chart
behind the scene. Drag the time slider to a decision and look at where the gain is: on the side of the
ring from which the faces that tell the models apart can be seen.""",
    ),
    (
        "code",
        """\
from pathlib import Path
from lab.viz.view3d import show_page

if view3d is None:
    print(no_view3d)
else:
    page = view3d.save(Path("out") / "identification_3d.html")
    rings = [st for st in view3d.steps if "/ring/candidates" in st.nodes]
    print(f"{len(view3d.steps) - 1} frames, {len(rings)} rings of candidate views; the page: {page}")
    gains = rings[-1].nodes["/ring/candidates"].props["gains"]
    assert 1 <= len(rings) <= len(agent.decisions) and np.array_equal(gains, agent.decisions[-1].gains, equal_nan=True)
    display(show_page(page))
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
