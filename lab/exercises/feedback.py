"""What a check of :mod:`lab.exercises` returns, and the helpers every check is made of.

:func:`call_answer` runs the student's function (a stub is "not attempted yet", an exception one line of
feedback), :func:`answer_array` takes its output as an array of the expected shape (a transposed shape is
named), :func:`close` compares within a tolerance (a NaN fails), :func:`verdict` turns the comparison and
the :class:`Mistake` list into :class:`Feedback`, and :func:`checked` wraps a check so that an early stop
becomes its Feedback.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Feedback", "Mistake", "Status", "answer_array", "call_answer", "checked", "close", "verdict"]


class Status(enum.Enum):
    """What a check found."""

    CORRECT = "correct"
    WRONG = "wrong"
    NOT_ATTEMPTED = "not attempted"
    ERROR = "error"  # the answer raised, or returned something that is not a number of the right shape


_MARK = {Status.CORRECT: "✔", Status.WRONG: "✘", Status.NOT_ATTEMPTED: "…", Status.ERROR: "✘"}


@dataclass(frozen=True)
class Feedback:
    """A check's verdict: its ``status``, one line of ``message`` for the student and, for a wrong
    answer, the ``hint`` key of the mistake it recognised (``None`` when it recognised none)."""

    exercise: str
    status: Status
    message: str
    hint: str | None = None

    @property
    def correct(self) -> bool:
        return self.status is Status.CORRECT

    def __str__(self) -> str:
        return f"{_MARK[self.status]} {self.exercise}: {self.message}"

    __repr__ = __str__  # a check as a cell's last line shows this line


class _Stop(Exception):
    """Raised inside a check to return a Feedback early (not attempted, raised, wrong shape)."""

    def __init__(self, feedback: Feedback):
        self.feedback = feedback


@dataclass(frozen=True)
class Mistake:
    """A mistake a check recognises: ``key``, what to tell the student, and the output it produces
    (an array to compare with) or a predicate on the student's output."""

    key: str
    message: str
    output: object = None
    test: Callable[[np.ndarray], bool] | None = None


def call_answer(name: str, fn, *args):
    """Run the student's function; stop with "not attempted" or "raised" feedback."""
    if fn is None:
        raise _Stop(
            Feedback(name, Status.NOT_ATTEMPTED, "not attempted yet: write the function, then run the check")
        )
    try:
        with np.errstate(all="ignore"):  # a NaN the answer makes is judged below, not warned about
            out = fn(*args)
    except NotImplementedError:
        raise _Stop(
            Feedback(
                name,
                Status.NOT_ATTEMPTED,
                "not attempted yet: replace `raise NotImplementedError` by your code",
            )
        ) from None
    except Exception as e:  # the student's code: any error becomes one line of feedback
        raise _Stop(Feedback(name, Status.ERROR, f"your function raised {type(e).__name__}: {e}")) from None
    if out is None or out is Ellipsis:
        raise _Stop(Feedback(name, Status.NOT_ATTEMPTED, "not attempted yet: your function returns nothing"))
    return out


def answer_array(name: str, out, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """The output as a float array of ``shape``; a transposed shape is named as such."""
    try:
        a = np.asarray(out, dtype=float)
    except (TypeError, ValueError):
        raise _Stop(
            Feedback(name, Status.ERROR, f"returned {type(out).__name__}, not an array of numbers")
        ) from None
    if shape is not None and a.shape != shape:
        if a.ndim == 2 and a.shape == shape[::-1]:
            raise _Stop(
                Feedback(
                    name,
                    Status.WRONG,
                    f"transposed axes: the shape is {a.shape}, it should be {shape}",
                    "transposed",
                )
            )
        if a.size == math.prod(shape):
            a = a.reshape(shape)  # e.g. (n,) for (n, 1): the same numbers
        else:
            raise _Stop(Feedback(name, Status.ERROR, f"the shape is {a.shape}, it should be {shape}"))
    return a


def close(got, want, tol: float) -> bool:
    """``got`` within ``tol`` (absolute, or relative to ``want``'s size where that is larger) of ``want``;
    NaN fails."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    if got.shape != want.shape:
        return False
    scale = max(1.0, float(np.max(np.abs(want)))) if want.size else 1.0
    err = float(np.max(np.abs(got - want))) if got.size else 0.0
    return bool(err <= tol * scale)


def verdict(
    name: str, got: np.ndarray, want: np.ndarray, tol: float, mistakes: Sequence[Mistake], fallback: str
):
    """Correct; else the first recognised mistake; else a NaN; else ``fallback``."""
    if close(got, want, tol):
        return Feedback(name, Status.CORRECT, "correct")
    for m in mistakes:
        hit = m.test(got) if m.test is not None else close(got, m.output, tol)
        if hit:
            return Feedback(name, Status.WRONG, m.message, m.key)
    if not np.all(np.isfinite(got)):
        return Feedback(
            name, Status.WRONG, "your answer holds NaN or infinity where a number is expected", "nan"
        )
    return Feedback(name, Status.WRONG, fallback)


def checked(fn):
    """Turn the early-stop exception of a check into its Feedback."""

    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except _Stop as s:
            return s.feedback

    wrapper.__name__, wrapper.__qualname__, wrapper.__doc__ = fn.__name__, fn.__qualname__, fn.__doc__
    wrapper.__module__ = fn.__module__
    return wrapper
