"""How an assignment's graded tests are written: a registry with points and visibility, and checks
whose failure messages say what is wrong and where to look.

A graded test is a plain function of one argument, the :class:`~lab.grading.child.Submission` proxy.
It calls the student's functions through the proxy (each call runs in the child process and comes back
as a value), compares what comes back against an independent oracle (SciPy, networkx, OpenCV, finite
differences, the paper's equation written out in the test) and either returns (pass: full points, an
optional string is shown as the test's output) or raises :class:`Fail` with a message for the student.
Exceptions, timeouts and crashes of the student's code are turned into failures by the runner.

.. code-block:: python

    suite = TestSuite("ekf")

    @suite.test("measurement_jacobian: C matches central differences of H", points=3,
                target="measurement_jacobian")
    def jacobian_fd(sub):
        C = as_array(sub.measurement_jacobian(X, b), "measurement_jacobian(X, b_O)", shape=(3 * n, 6))
        check_close(C, C_fd, "measurement_jacobian(X, b_O)", atol=1e-6)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

__all__ = [
    "Visibility",
    "GradedTest",
    "TestSuite",
    "Fail",
    "fail",
    "as_array",
    "as_float",
    "check_close",
    "fmt",
]


class Visibility(Enum):
    """When a student sees a test on Gradescope (the values are Gradescope's)."""

    VISIBLE = "visible"  # at once
    AFTER_DUE_DATE = "after_due_date"
    AFTER_PUBLISHED = "after_published"
    HIDDEN = "hidden"  # never (the instructor sees it)


@dataclass(frozen=True)
class GradedTest:
    """One weighted test.

    Attributes
    ----------
    id : str
        Stable identifier (the function's name): CSV columns and tests refer to it.
    name : str
        What the student reads: ``"function: property checked"``.
    points : float
    target : str
        The student function this test is about.
    uses : tuple of str
        Other student functions the tested one is expected to call (their failures are pointed out).
    visibility : Visibility
    timeout_s : float or None
        Wall time the student's code may take in this test (None: the assignment's default).
    func : callable
        ``func(sub) -> str | None``; raises :class:`Fail`.
    """

    id: str
    name: str
    points: float
    target: str
    uses: tuple[str, ...]
    visibility: Visibility
    timeout_s: float | None
    func: Callable = field(repr=False)


class TestSuite:
    """The graded tests of one assignment, in the order they are reported."""

    __test__ = False  # not a pytest class

    def __init__(self, assignment: str):
        self.assignment = assignment
        self.tests: list[GradedTest] = []

    def test(
        self,
        name: str,
        *,
        points: float,
        target: str,
        uses: tuple[str, ...] = (),
        visibility: Visibility | str = Visibility.AFTER_DUE_DATE,
        timeout_s: float | None = None,
    ):
        """Decorator registering ``func(sub)`` as a graded test."""
        vis = Visibility(visibility)
        if not points > 0:
            raise ValueError(f"points must be > 0, got {points}")

        def register(func):
            if any(t.id == func.__name__ for t in self.tests):
                raise ValueError(f"two graded tests are called {func.__name__}")
            self.tests.append(
                GradedTest(func.__name__, name, float(points), target, tuple(uses), vis, timeout_s, func)
            )
            return func

        return register

    @property
    def max_score(self) -> float:
        return float(sum(t.points for t in self.tests))


class Fail(Exception):
    """A graded check failed; the message is shown to the student."""


def fail(message: str):
    raise Fail(message)


def fmt(x, precision: int = 4) -> str:
    """A short readable rendering of a number or array for messages."""
    a = np.asarray(x)
    if a.ndim == 0:
        return f"{float(a):.{precision}g}" if a.dtype.kind in "fiub" else repr(x)
    return np.array2string(a, precision=precision, suppress_small=True, threshold=40, max_line_width=100)


def as_array(value, what: str, shape: tuple | None = None, finite: bool = True, dtype=float) -> np.ndarray:
    """Turn a returned value into an array, checking its shape and that it is finite.

    ``shape`` may hold ``None`` for a free axis. Raises :class:`Fail` naming ``what`` (e.g.
    ``"measurement_jacobian(X, b_O)"``) and the shape that was expected.
    """
    if value is None:
        fail(f"{what} returned None: did you forget the return statement?")
    try:
        a = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as e:
        fail(f"{what} returned {type(value).__name__} that is not a numeric array ({e})")
    if shape is not None:
        ok = a.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, a.shape, strict=False))
        if not ok:
            want = (
                "("
                + ", ".join("any" if s is None else str(s) for s in shape)
                + ("," if len(shape) == 1 else "")
                + ")"
            )
            fail(f"{what} returned shape {a.shape}; expected shape {want}")
    if finite and a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))
        first = tuple(int(i) for i in bad[0]) if a.ndim else ()
        fail(
            f"{what} returned {int(bad.shape[0]) if a.ndim else 1} non-finite value(s) (NaN or inf), "
            f"first at index {first}: {fmt(a[first] if a.ndim else a)}"
        )
    return a


def as_float(value, what: str, finite: bool = True) -> float:
    """A returned scalar (a Python number, a 0-d or one-element array) as float; Fail otherwise."""
    a = as_array(value, what, finite=finite)
    if a.size != 1:
        fail(f"{what} returned an array of shape {a.shape}; expected a single number")
    return float(a.reshape(()))


def check_close(actual, expected, what: str, rtol: float = 1e-7, atol: float = 1e-9, hint: str = "") -> None:
    """Fail unless ``actual`` equals ``expected`` entry-wise within ``atol + rtol * |expected|``.

    NaN-safe: a NaN in either fails, and so does an infinity not matched by the same one. The message
    names the worst entry (a NaN first), its value and the expected one, and adds ``hint``.
    """
    a = np.asarray(actual, dtype=float)
    e = np.asarray(expected, dtype=float)
    if a.shape != e.shape:
        fail(f"{what} has shape {a.shape}; expected {e.shape}")
    with np.errstate(invalid="ignore"):  # inf - inf is NaN: fails below like any NaN
        err = np.abs(a - e)
        tol = atol + rtol * np.abs(e)
        ok = np.where(np.isinf(e), a == e, err <= tol)  # False where either is NaN: a NaN never passes
        if np.all(ok):
            return
        excess = np.where(ok, -np.inf, np.nan_to_num(err - tol, nan=np.inf, posinf=np.inf))
    k = np.unravel_index(int(np.argmax(excess)), err.shape)
    where = f" at index {tuple(int(i) for i in k)}" if a.ndim else ""
    msg = (
        f"{what} is wrong{where}: got {fmt(a[k])}, expected {fmt(e[k])} "
        f"({int(np.count_nonzero(~ok))} of {err.size} entries off; largest error {fmt(np.max(err), 3)}, "
        f"tolerance {fmt(atol, 3)} + {fmt(rtol, 3)} * |expected|)"
    )
    fail(msg + (f"\n{hint}" if hint else ""))
