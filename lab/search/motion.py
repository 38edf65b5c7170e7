r"""The prediction step of the probability map M_p: where a *moving* object may have gone since.

The search paper assumes a stationary object, ``P(h_ij^k = 1 | Y_1:k-1) = P(h_ij^{k-1} = 1 | Y_1:k-1)``
(Sec. III-A, after Eq. (2)). For an object that moves (Chung and Burdick's moving target, the
paper's [5]) the prior of Eq. (1) is instead the Chapman-Kolmogorov prediction through a motion model
``T``:

.. math::

    P(h_{ij}^k = 1 \mid Y_{1:k-1}) = \sum_{m,n} T_{ij,mn}(\Delta t)\; P(h_{mn}^{k-1} = 1 \mid Y_{1:k-1})
        \quad (1')

**The motion model.** The object moves at most ``v`` [m/s] (its speed bound), over the cells the
robot may believe passable. In every interval ``tau <= r / v`` (``r`` the cell side [m]) it stays in
its cell or steps to one of its 4 neighbours; a step into a blocked cell (or off the map) is refused
and the object stays. With ``q(tau) = q_max v tau / r`` the share of a cell's mass that moves to each
passable neighbour in the interval, and ``m_c`` in {0, 1} the passability of cell ``c``:

.. math::

    P'_c = P_c + q(\tau) \sum_{n \in N_4(c)} m_c\, m_n\, (P_n - P_c)                     \quad (P1)

Each pair of neighbours exchanges ``q m_c m_n (P_n - P_c)`` in equal and opposite amounts, so the
total mass is conserved exactly, a blocked cell neither gives nor receives (no mass enters an
obstacle, and none crosses a line of blocked cells), and with ``q_max <= 1/4`` no cell goes
negative. A blocked cell keeps the mass it holds (a prediction does not decide that an object on a
shelf has left it). ``Delta t`` is cut into ``n = ceil(v Delta t / r)`` equal intervals, so that

* **the speed bound:** after ``Delta t`` mass has moved at most ``n`` cells (4-neighbour steps), at most
  ``v Delta t + r`` from where it was;
* **the spread:** on an open grid each interval is a convolution with the 5-point kernel
  ``[[0, q, 0], [q, 1 - 4q, q], [0, q, 0]]``, which adds ``2 q r^2`` to the variance along each
  axis; summed over the intervals, ``sigma^2 = 2 D Delta t`` per axis with the diffusion coefficient
  ``D = q_max v r`` [m^2/s], however ``Delta t`` is cut (the central limit: a Gaussian of that
  variance for large ``n``);
* **speed 0 is a no-op:** ``v = 0`` or ``Delta t = 0`` returns ``P`` unchanged, bit for bit (the
  static search is the paper's).

``q_max = 1/5`` (:data:`Q_MAX`): in each interval the object is equally likely to stay or to take
any of the 4 steps, a lazy random walk at the speed bound.

**Which cells are passable** is the robot's belief, not the truth: its costmap's OBSTACLE cells block
and FREE and UNKNOWN cells pass (:func:`passable_from_costmap`). A miss (the local search's ``y = 0``)
lowers the cells it covered through Eq. (1); the prediction then lets mass flow back into them at the
rate the speed bound allows.

**Surfaces: an object on a table's top.** The map is a floor grid, and a cell under a table holds the
belief that the object is anywhere in that column, on the top too. The costmap marks a table's cells
OBSTACLE (its top at 0.75 m is something the robot's head would hit), so with a passable mask a
table-top object's mass is frozen where it lies: it is kept, but never moves over the top, and a miss
on the top never fills in from the cells beside it. A carrier neither climbs onto a table nor drives
off one, so the motion model has *surfaces* instead: ``m_c`` becomes a label ``s_c`` (0 blocks) and
mass moves only between neighbours of the same surface,

.. math::

    P'_c = P_c + q(\tau) \sum_{n \in N_4(c)} [s_c = s_n \neq 0]\, (P_n - P_c)              \quad (P2)

with the same exact conservation and speed bound, and no mass crossing between surfaces: the floor's
stays on the floor, a table top's on the top (a passable mask is the labels 1 and 0, and (P2) is (P1)).
:func:`surfaces_from_costmap` labels the robot's costmap, not the truth: FREE and UNKNOWN cells are the
floor (1), OBSTACLE cells the raised surface (2). The robot is not told where the tables are (its map
is the room's floor, and the table's cells become raised once it has seen them), nor which surface the
object is on, so every raised cell's mass moves among raised neighbours: a table top's over the top,
and a crate's or a wall's (what the prior and the colour peaks gave them) only over that obstacle, as
it stayed on it before. The alternative, the room's plan of its tables, is not something the robot is
given; and a table's cells that the costmap has not seen yet are floor (UNKNOWN), so until then the
two exchange mass as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lab.errors import ConfigError
from lab.navigation.costmap import CellState
from lab.navigation.grid import GridSpec

__all__ = [
    "FLOOR",
    "Q_MAX",
    "RAISED",
    "MotionModel",
    "diffusion_coefficient",
    "diffuse_step",
    "passable_from_costmap",
    "predict",
    "surfaces_from_costmap",
]

#: The labels of :func:`surfaces_from_costmap`: the floor (FREE and UNKNOWN cells) and the raised cells
#: (OBSTACLE: a table's top among them); 0 would block.
FLOOR, RAISED = 1, 2

#: The share of a cell's mass that moves to each of its 4 neighbours in one interval ``r / v``: the
#: object stays or takes any of the 4 steps with equal probability (must be <= 1/4 for P >= 0).
Q_MAX = 0.2


@dataclass(frozen=True)
class MotionModel:
    """The object's motion model of Eq. (P1).

    Attributes
    ----------
    speed_mps : float [m/s]
        The speed bound ``v``; 0: a stationary object (the prediction is a no-op).
    q_max : float
        The share of a cell's mass moving to each passable neighbour per interval ``r / v``, in (0, 1/4].
    """

    speed_mps: float = 0.0
    q_max: float = Q_MAX

    def __post_init__(self):
        if not (math.isfinite(self.speed_mps) and self.speed_mps >= 0):
            raise ConfigError(f"speed_mps must be a finite number >= 0 m/s, got {self.speed_mps!r}")
        if not 0.0 < self.q_max <= 0.25:
            raise ConfigError(f"q_max must be within (0, 1/4], got {self.q_max!r}")

    @property
    def moving(self) -> bool:
        """True when the prediction does anything (a speed bound above 0)."""
        return self.speed_mps > 0


def diffusion_coefficient(model: MotionModel, resolution: float) -> float:
    """``D = q_max v r`` [m^2/s]: the variance along each axis grows as ``2 D Delta t`` on an open grid."""
    return model.q_max * model.speed_mps * resolution


def diffuse_step(P: np.ndarray, passable: np.ndarray, q: float) -> np.ndarray:
    """One interval of Eq. (P1), ``P'_c = P_c + q sum_n m_c m_n (P_n - P_c)`` over the 4 neighbours, or
    with surface labels Eq. (P2), ``P'_c = P_c + q sum_n [s_c = s_n != 0] (P_n - P_c)``.

    Parameters
    ----------
    P : ndarray, shape (nx, ny)
    passable : ndarray of bool or int, shape (nx, ny)
        ``m_c``: True where the object may be or pass; or ``s_c``, each cell's surface label (0:
        blocked; mass moves only between neighbours of the same label).
    q : float
        Share per neighbour, within [0, 1/4].

    Returns
    -------
    ndarray, shape (nx, ny)
        A new array, with the same total as ``P``.
    """
    s = np.asarray(passable)
    out = P.copy()
    # the edges mass crosses: both cells on one surface (both passable, for a mask)
    lx = ((s[1:, :] == s[:-1, :]) & (s[1:, :] != 0)).astype(float)
    ly = ((s[:, 1:] == s[:, :-1]) & (s[:, 1:] != 0)).astype(float)
    fx = q * lx * (P[1:, :] - P[:-1, :])  # from cell (i+1, j) into (i, j)
    fy = q * ly * (P[:, 1:] - P[:, :-1])  # from cell (i, j+1) into (i, j)
    out[:-1, :] += fx
    out[1:, :] -= fx
    out[:, :-1] += fy
    out[:, 1:] -= fy
    return out


def predict(
    P: np.ndarray, passable: np.ndarray, dt_s: float, model: MotionModel, resolution: float
) -> np.ndarray:
    """Eq. (1'): the map after ``dt_s`` [s] of motion under ``model``, by ``n`` intervals of Eq. (P1).

    Parameters
    ----------
    P : ndarray, shape (nx, ny)
        ``P(h^{k-1} | Y_1:k-1)``.
    passable : ndarray of bool or int, shape (nx, ny)
        Where the object may go (:func:`passable_from_costmap`), or the cells' surfaces
        (:func:`surfaces_from_costmap`, Eq. (P2)).
    dt_s : float [s]
        Time since the last update (>= 0).
    model : MotionModel
    resolution : float [m]
        The cell side ``r``.

    Returns
    -------
    ndarray, shape (nx, ny)
        ``P(h^k | Y_1:k-1)``; ``P`` itself (not a copy) when the model does not move or ``dt_s`` is 0.
    """
    if not (math.isfinite(dt_s) and dt_s >= 0):
        raise ConfigError(f"dt_s must be a finite number >= 0 s, got {dt_s!r}")
    if passable.shape != P.shape:
        raise ConfigError(f"passable mask shape {passable.shape} does not match the map {P.shape}")
    cells = model.speed_mps * dt_s / resolution  # how many cells the object may have crossed
    if cells <= 0:
        return P
    n = math.ceil(cells)
    q = model.q_max * cells / n  # q(tau) = q_max v tau / r with tau = dt / n
    for _ in range(n):
        P = diffuse_step(P, passable, q)
    return P


def passable_from_costmap(
    state: np.ndarray, costmap_spec: GridSpec, map_spec: GridSpec, blocked_share: float = 0.5
) -> np.ndarray:
    """The probability map's passable cells from the robot's costmap (its belief, not the truth).

    A map cell is blocked when at least ``blocked_share`` of the costmap cells whose centres fall in it
    are OBSTACLE; FREE and UNKNOWN pass. A map cell with no costmap cell in it passes.

    Parameters
    ----------
    state : ndarray of CellState, shape costmap_spec.shape
    costmap_spec, map_spec : GridSpec
    blocked_share : float
        Within (0, 1].

    Returns
    -------
    ndarray of bool, shape map_spec.shape
    """
    if not 0.0 < blocked_share <= 1.0:
        raise ConfigError(f"blocked_share must be within (0, 1], got {blocked_share!r}")
    X, Y = costmap_spec.cell_centers()
    ij, inside = map_spec.cells_of(np.column_stack([X.ravel(), Y.ravel()]))
    nx, ny = map_spec.shape
    k = ij[inside, 0] * ny + ij[inside, 1]
    obstacle = (np.asarray(state).ravel() == CellState.OBSTACLE)[inside]
    total = np.bincount(k, minlength=nx * ny)
    blocked = np.bincount(k, weights=obstacle.astype(float), minlength=nx * ny)
    share = np.divide(blocked, total, out=np.zeros(nx * ny), where=total > 0)
    return (share < blocked_share).reshape(nx, ny)


def surfaces_from_costmap(
    state: np.ndarray, costmap_spec: GridSpec, map_spec: GridSpec, blocked_share: float = 0.5
) -> np.ndarray:
    """The probability map's cells labelled by surface for Eq. (P2), from the robot's costmap (its
    belief, not the truth): :data:`RAISED` where :func:`passable_from_costmap` blocks (a table's top
    among them), :data:`FLOOR` elsewhere.

    Parameters
    ----------
    state : ndarray of CellState, shape costmap_spec.shape
    costmap_spec, map_spec : GridSpec
    blocked_share : float
        Within (0, 1]: as :func:`passable_from_costmap`.

    Returns
    -------
    ndarray of int8, shape map_spec.shape
    """
    floor = passable_from_costmap(state, costmap_spec, map_spec, blocked_share)
    return np.where(floor, FLOOR, RAISED).astype(np.int8)
