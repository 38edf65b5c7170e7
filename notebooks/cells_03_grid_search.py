"""Notebook 03: grid search.

``make_notebooks.py`` writes these cells as ``03_grid_search.ipynb``: ``INTRO``, then its common set-up
cell, then ``CELLS``.
"""

INTRO = [
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
    (
        "md",
        r"""**Learning objectives.** After this notebook you can:

1. write the detection model with its false-alarm and missed-detection rates (Eq. (2)) and update the probability map after a detection or a miss (Eqs. (1)-(3));
2. explain how a failed search moves probability to the other cells, and why a detector needs $\alpha + \beta < 1$;
3. find the places that look like the object by colour back-projection, and put them on the map with stereo;
4. plan a path on a stereo costmap with A* and an admissible heuristic, and verify it against Dijkstra;
5. run the whole search, and choose the next cell by probability or by detection rate.

**Prerequisites:** notebooks [00](00_simulator_and_stereo.ipynb) and [01](01_pose_ekf.ipynb) (the local search uses the pose EKF); Bayes' rule; graphs and shortest paths (Dijkstra).

**Time:** about 90 minutes (reading 40, exercises 30, the whole search 20). The exercises marked *checked* answer back when you run their cell: "correct", or a hint
that names your mistake (`lab.exercises`); until you write your code they say "not attempted yet". This
notebook prepares the [`search` assignment](../assignments/search/README.md); the course plan is
[docs/course.md](../docs/course.md).""",
    ),
]

SUMMARY = [
    (
        "md",
        r"""## Summary

* The probability map holds $P(h_{ij} = 1 \mid \mathbf{Y})$ for every cell and sums to 1; Eqs. (1)-(3) update it with each detection or miss.
* A miss moves the searched cell's mass to all other cells in proportion; the global search's positive detections use a $\beta$ that grows away from the measured cell.
* Colour back-projection of the histogram ratio finds object-like patches; dense stereo puts them on the map.
* A* with the octile heuristic finds the cheapest path on the costmap, as Dijkstra does, and the agent closes the loop: scan, drive, look, update.

**Next:** [04 The real robot](04_real_robot.ipynb). **Assignment:** [`search`](../assignments/search/README.md) (its
README says what to write and how it is graded).""",
    ),
]

CELLS = [
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
        r"""**Exercise 1 (checked): the detection model.** Write `my_detection_likelihood(shape, cell, detected, alpha, beta)`: the array, of the map's shape, whose entry $(i, j)$ is $P(y \mid h_{ij} = 1)$ of Eq. (2), for a detection (`detected=True`, $y = 1$) and for a miss. (It is `detection_likelihood` of the `search` assignment.)""",
    ),
    (
        "code",
        """\
from lab.exercises import check_detection_likelihood

def my_detection_likelihood(shape, cell, detected, alpha, beta):
    raise NotImplementedError   # your code: an array of `shape`

check_detection_likelihood(my_detection_likelihood)
""",
    ),
    (
        "md",
        r"""**Exercise 2 (checked): the map update.** Write `my_update_probability_map(P, cell, detected, alpha, beta)`: the posterior map of Eqs. (1)-(3) (use your detection model). The check takes the posterior from the joint distribution of the hypotheses and the measurement.""",
    ),
    (
        "code",
        """\
from lab.exercises import check_map_update

def my_update_probability_map(P, cell, detected, alpha, beta):
    P = np.asarray(P, float)
    raise NotImplementedError   # your code: the posterior, of P's shape, summing to 1

check_map_update(my_update_probability_map)
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
gcfg = GlobalSearchConfig()              # gcfg.detection: alpha = 0.05, lambda = growth_m = 0.2 m, beta_min = beta = 0.1
cell = room.world_to_cell(1.0, 1.0)
X, Y = room.cell_centers()
d = np.hypot(X - room.cell_to_world(*cell)[0], Y - room.cell_to_world(*cell)[1])   # distance from c_uv [m]

fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
for P_n in (0.9, 0.7, 0.5):
    det = gcfg.detection
    beta0 = max(det.beta, 1 - P_n)
    B = growing_beta_field(room, cell, det.alpha, beta0, det.growth_m)
    reach = det.growth_m * math.log((1 - det.alpha) / beta0)
    assert np.isclose(1 - B[cell], P_n) and np.allclose(1 - B[d > reach + 1e-9], det.alpha)
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
from lab.search import ColourPeakDetection, ProbabilityMap
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
        pmap.observe(ColourPeakDetection(p.cell, p.strength, gcfg.detection))   # Eqs. (1)-(3), growing beta

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
        r"""**Exercise 3 (checked): A*'s heuristic.** On open floor where every cell costs at least $m_{min}$, the cheapest 8-connected path from a cell to the goal takes the diagonal as far as it can, then goes straight. Write `my_octile_heuristic(cell, goal, min_cost)` (in cell units: a straight step is 1, a diagonal one $\sqrt 2$, times the cost). The check compares with networkx's Dijkstra on an open grid. (It is `octile_heuristic` of the `search` assignment.)""",
    ),
    (
        "code",
        """\
from lab.exercises import check_octile_heuristic

def my_octile_heuristic(cell, goal, min_cost):
    raise NotImplementedError   # your code: a float, never more than the true cost

check_octile_heuristic(my_octile_heuristic)
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
2. Give the local search a larger $\beta$ (`from lab.search import DetectionModel, LocalSearchConfig,
   SearchAgentConfig`, then `config=SearchAgentConfig(local_search=LocalSearchConfig(detection=DetectionModel(0.05,
   0.5, neighbour_radius_m=0.45)))` in `run_search`) and search for the
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
from lab.search import detection_rates

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
    (
        "md",
        r"""## The search in 3D

The same search recorded as a 3D scene (`run_search(..., view3d=path)`, or `lab search --view3d FILE.html`):
the room, the robot's true (black) and estimated (green) paths with the localizer's 3-sigma ellipse, the
global scan's cameras and colour peaks (red), each local search's views (blue cameras), and the map
$M_p$ as a heat map (log colour scale) on the floor and again on the table and shelf tops at their
height (the map is a floor grid: a cell under the shelf holds the belief that the object is anywhere
in that column, on the shelf too), one step per event. Drag the time slider to watch the mass move as
each cell is searched. The page is self-contained: open the saved file in any browser, offline.""",
    ),
    (
        "code",
        """\
from pathlib import Path
from lab.errors import ConfigError
from lab.viz.view3d import show_page

page = Path("out") / "grid_search_3d.html"
try:
    res3d = run_search(target, seed=0, place=scene.body(target).pose, navigate=navigate,
                       max_time=60 if FAST else 400, view3d=page)
except ConfigError as e:   # the optional viewer is missing: the line says how to install it
    print(e)
else:
    print(f"{len(res3d.events)} events, one step each on the time slider; the page: {page}")
    display(show_page(page))
""",
    ),
    (
        "md",
        r"""## An object that moves: the prediction step

The paper assumes the object stays put: the prior of Eq. (1) is the last map,
$P(h^k_{ij} = 1 \mid \mathbf{Y}_{1:k-1}) = P(h^{k-1}_{ij} = 1 \mid \mathbf{Y}_{1:k-1})$. If it moves at
most $v$ m/s, the prior is the last map *moved* by a motion model $T$ over the time $\Delta t$ since:
$P(h^k_{ij}) = \sum_{mn} T_{ij,mn}(\Delta t)\, P(h^{k-1}_{mn})$. `lab.search.motion.predict` uses a lazy
random walk at the speed bound, in steps of one cell: every $r / v$ seconds each passable neighbour
receives a share $q$ of the difference, $P'_c = P_c + q \sum_n m_c m_n (P_n - P_c)$, so mass is
conserved and never enters or crosses an obstacle. Below: a miss empties a cell by a wall (left), and
the prediction lets the mass flow back over the next minute, but not through the wall. Move the speed.""",
    ),
    (
        "code",
        """\
from lab.search import DetectionModel, LocalSearchDetection, MotionModel, predict

pmap = ProbabilityMap(GridSpec((0.0, 0.0), 0.2, (25, 25)))
passable = np.ones(pmap.spec.shape, bool)
passable[15, 3:22] = False                                     # a wall the costmap has seen
pmap.P = np.where(passable, pmap.P, 0.0) / np.where(passable, pmap.P, 0.0).sum()
pmap.observe(LocalSearchDetection((12, 12), 0, DetectionModel(0.05, 0.1, neighbour_radius_m=0.45)))
speed_out = widgets.Output()
speed = widgets.FloatSlider(value=0.1, min=0.0, max=0.3, step=0.02, description="v [m/s]")

def show_motion(change=None):
    with speed_out:
        speed_out.clear_output(wait=True)
        fig, axes = plt.subplots(1, 4, figsize=(13, 3.2))
        P = pmap.P
        for ax, t in zip(axes, (0, 10, 30, 60)):
            Pt = predict(P, passable, t, MotionModel(speed.value), 0.2)
            assert abs(Pt.sum() - 1.0) < 1e-12 and np.all(Pt[~passable] == 0)
            ax.imshow(Pt.T, origin="lower", vmin=0, vmax=P.max())
            ax.set_title(f"{t} s after the miss: cell {Pt[12, 12] / P.max():.2f} of max")
            ax.set_xticks([]); ax.set_yticks([])
        plt.show()

speed.observe(show_motion, "value")
show_motion()
display(widgets.VBox([speed, speed_out]))
""",
    ),
    (
        "md",
        r"""### The same run, with and without the prediction

Now a real search for the toy block riding a carrier at 0.1 m/s (`run_search(..., moving=MovingOptions("random"))`,
which is `lab search --object toy_block --moving random`). Its map changes in two ways only: an
observation (Eqs. (1)-(3)) and a prediction (Eq. (1')). `MapLog` (`lab.search.map_log`) records both
during the run, and *replays* the same observations on the same prior: without the prediction steps
(the paper's static map) and with them at any speed bound. The robot's decisions stay those of the
run (the replay shows what the other map would have believed, not where another search would have
looked). Left: the static map; right: the predicting one at the slider's speed (0.1 m/s is the run's
own map). The white line is the robot's path up to that update, `+` where the toy block started and
`x` where it stood at the end; each map has its own colour scale (its maximum in the title). Move the
update and the speed: after the global search the two agree;
after a miss the static map keeps the missed cell empty, while the predicting one lets mass flow back
into it and spreads the colour peaks at the speed bound.""",
    ),
    (
        "code",
        """\
from lab.runs.moving import MovingOptions
from lab.search.map_log import MapLog

log = MapLog()
# FAST: the global search and the first local search only, rendered at the camera's own resolution
moving = run_search("toy_block", seed=0, place=scene.body("toy_block").pose, navigate=navigator_factory,
                    max_time=40 if FAST else 300, supersample=1 if FAST else 2,
                    moving=MovingOptions("random", speed_mps=0.1), attach=log.attach)
mj = moving.to_json()
print("found" if mj["found"] else "not found", "-", mj["reason"])
print("the carrier:", {k: mj["moving"][k] for k in ("support", "legs", "path_length_m")})
static = log.replay(None)                                       # the same observations, no prediction
assert static and all(abs(P.sum() - 1.0) < 1e-9 for _, P in static)
assert all(np.array_equal(a, b) for (_, a), (_, b) in zip(static, log.replay(MotionModel(0.0))))  # v = 0: static
(x0, y0), r, (nx, ny) = log.spec.origin_xy, log.spec.resolution, log.spec.shape
path = moving.trace.trajectory                                  # (t, x, y, theta) of the robot
start_xy, end_xy = mj["place"][:2], mj["true_pose"]["position_m"][:2]
moment = widgets.IntSlider(value=len(static) - 1, min=0, max=len(static) - 1, description="update")
v_run = widgets.FloatSlider(value=0.1, min=0.0, max=0.3, step=0.02, description="v [m/s]")
run_out = widgets.Output()

def side_by_side(change=None):
    with run_out:
        run_out.clear_output(wait=True)
        t, P_static = static[moment.value]
        _, P_pred = log.replay(MotionModel(v_run.value))[moment.value]
        fig, axes = plt.subplots(1, 2, figsize=(10, 6))
        for ax, P, title in ((axes[0], P_static, "without prediction"),
                             (axes[1], P_pred, f"with prediction, v = {v_run.value:.2f} m/s")):
            ax.imshow(P.T, origin="lower", extent=(x0, x0 + nx * r, y0, y0 + ny * r), vmin=0)  # own scale
            before = path[path[:, 0] <= t]
            ax.plot(before[:, 1], before[:, 2], "w-", lw=1)
            ax.plot(*start_xy, "w+", ms=12, mew=2)
            ax.plot(*end_xy, "rx", ms=10, mew=2)
            ax.set_title(f"{title}\\nt = {t:.0f} s, max P = {P.max():.3f}")
        plt.show()

moment.observe(side_by_side, "value")
v_run.observe(side_by_side, "value")
side_by_side()
display(widgets.VBox([widgets.HBox([moment, v_run]), run_out]))
""",
    ),
    (
        "md",
        r"""`lab search --object toy_block --moving random` runs the whole search with the object on a carrier
(`--surface table`: on a table's top, where the prediction keeps its mass on the top's cells, the
raised cells of the costmap); `--static-map` is the same run without the prediction step, and
`lab eval search --moving random` runs both on the same trials. At speed 0 the prediction changes
nothing, bit for bit: the paper's search.""",
    ),
]
