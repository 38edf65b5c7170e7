"""What grading produces: Gradescope's ``results.json``, a terminal summary, and a class CSV.

Gradescope's autograder reads ``/autograder/results/results.json``:

.. code-block:: json

    {"score": 17.0, "execution_time": 3.2, "output": "...", "visibility": "visible",
     "tests": [{"name": "...", "number": "1", "score": 2.0, "max_score": 2.0, "status": "passed",
                "output": "...", "visibility": "visible", "tags": ["measurement_model"],
                "extra_data": {"id": "measurement_model_eq3", "duration_s": 0.2}}]}

``score`` is the sum of the tests' scores; ``max_score`` and ``extra_data`` are extras that Gradescope
ignores and our scripts read.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from lab.grading.limits import TEST_OUTPUT_CHARS, clean, fit_results
from lab.grading.suite import GradedTest
from lab.io import atomic_output

if TYPE_CHECKING:
    from lab.grading.assignments import Assignment

__all__ = ["TestResult", "GradeReport", "write_scores_csv", "INSECURE"]

INSECURE = "INSECURE: graded without a sandbox (--insecure), for practice only; this score does not count"


@dataclass
class TestResult:
    """The outcome of one graded test (``output`` may gain a note after all tests ran)."""

    test: GradedTest
    score: float
    status: str  # "passed" or "failed"
    output: str
    duration_s: float
    refused: tuple[str, ...] = ()  # what the sandbox refused the student's code in this test

    __test__ = False


@dataclass
class GradeReport:
    """All results of one submission for one assignment.

    Attributes
    ----------
    assignment : Assignment
    submission : str
    tests : list of TestResult
        In the suite's order.
    execution_time_s : float
        Wall time of the whole grading run.
    error : str or None
        Set when no test could run (no module, a refused file, or it does not import); every test
        then carries it.
    sandbox : str
        How the student's code was isolated (:class:`~lab.grading.isolation.Sandbox` ``kind``:
        ``"bwrap-uid"``, ``"bwrap-userns"``, ``"uid"``); ``"none"`` means graded with ``--insecure``,
        which every test's output says, and ``results.json``'s ``extra_data.secure`` is false.
    """

    assignment: Assignment
    submission: str
    tests: list[TestResult]
    execution_time_s: float
    error: str | None
    sandbox: str = "unknown"

    @property
    def refused(self) -> list[str]:
        """Everything the sandbox refused, over all tests (each once)."""
        seen: list[str] = []
        for r in self.tests:
            seen += [n for n in r.refused if n not in seen]
        return seen

    @property
    def score(self) -> float:
        return float(sum(r.score for r in self.tests))

    @property
    def max_score(self) -> float:
        return float(sum(r.test.points for r in self.tests))

    def by_id(self) -> dict[str, TestResult]:
        return {r.test.id: r for r in self.tests}

    def failed_ids(self) -> set[str]:
        return {r.test.id for r in self.tests if r.status != "passed"}

    def to_gradescope(self) -> dict:
        """Gradescope's results.json (plus ``max_score`` and ``extra_data``)."""
        tests = [
            {
                "name": r.test.name,
                "number": str(i + 1),
                "score": round(r.score, 6),
                "max_score": r.test.points,
                "status": r.status,
                "output": clean(r.output, TEST_OUTPUT_CHARS),
                "visibility": r.test.visibility.value,
                "tags": sorted({r.test.target, *r.test.uses}),
                "extra_data": {
                    "id": r.test.id,
                    "duration_s": round(r.duration_s, 3),
                    **({"refused": [clean(n, 300) for n in r.refused]} if r.refused else {}),
                },
            }
            for i, r in enumerate(self.tests)
        ]
        head = f"{self.assignment.name}: {self.score:g} / {self.max_score:g} points"
        if self.sandbox == "none":
            head = f"{INSECURE}\n{head}"
        if self.error:
            head += f"\n{clean(self.error, TEST_OUTPUT_CHARS)}"
        hidden = sum(1 for r in self.tests if r.test.visibility.value != "visible")
        if hidden:
            head += f"\n{hidden} of {len(self.tests)} tests are shown after the due date or not at all."
        return {
            "score": round(self.score, 6),
            "max_score": self.max_score,
            "execution_time": round(self.execution_time_s, 2),
            "output": head,
            "visibility": "visible",
            "stdout_visibility": "hidden",
            "tests": tests,
            "extra_data": {
                "assignment": self.assignment.name,
                "submission": clean(self.submission, 1000),
                "sandbox": self.sandbox,
                "secure": self.sandbox != "none",
                "refused": [clean(n, 300) for n in self.refused],
            },
        }

    @classmethod
    def from_gradescope(cls, assignment: Assignment, data: dict, error: str | None) -> GradeReport:
        """The report whose :meth:`to_gradescope` is ``data`` (a report graded elsewhere, e.g. on a
        cluster's worker, sent back as its results.json): each test found by its id in the suite."""
        by_id = {t.id: t for t in assignment.load_suite().tests}
        results = [
            TestResult(
                by_id[t["extra_data"]["id"]],
                float(t["score"]),
                t["status"],
                t["output"],
                float(t["extra_data"]["duration_s"]),
                tuple(t["extra_data"].get("refused", ())),
            )
            for t in data["tests"]
        ]
        extra = data["extra_data"]
        return cls(
            assignment, extra["submission"], results, float(data["execution_time"]), error, extra["sandbox"]
        )

    def write_json(self, path: str | Path) -> Path:
        """Write results.json atomically (a temporary file, flushed to disk, renamed over the target),
        then read it back: an error if what is there is not what was meant to be written. It stays
        under 1 MB whatever the submission sent (:func:`~lab.grading.limits.fit_results`)."""
        path = Path(path)
        text = fit_results(self.to_gradescope())
        with atomic_output(path) as tmp, open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        if json.loads(path.read_text()) != json.loads(text):
            raise OSError(f"{path} does not hold the results just written to it")
        return path

    def summary(self) -> str:
        """A readable summary for the terminal: one line per test, the message under each failure (no
        control character of the submission's reaches the terminal: :func:`~lab.grading.limits.clean`)."""
        lines = [
            f"{self.assignment.name} ({self.assignment.title})",
            f"submission: {clean(self.submission, 1000)}",
            f"isolation: {self.sandbox}" + (" (INSECURE)" if self.sandbox == "none" else ""),
        ]
        if self.sandbox == "none":
            lines.insert(0, INSECURE)
        width = max(len(r.test.name) for r in self.tests) if self.tests else 0
        width = min(width, 70)
        for r in self.tests:
            mark = "PASS" if r.status == "passed" else "FAIL"
            lines.append(f"  {mark} {r.score:4g}/{r.test.points:<3g} {r.test.name:<{width}}  [{r.test.id}]")
            if r.status != "passed" and r.output:
                for ln in clean(r.output, TEST_OUTPUT_CHARS).splitlines()[:12]:
                    lines.append(f"         {ln}")
        pct = 100.0 * self.score / self.max_score if self.max_score else 0.0
        lines.append(
            f"score: {self.score:g} / {self.max_score:g} ({pct:.0f} %) in {self.execution_time_s:.1f} s"
        )
        return clean("\n".join(lines))


def write_scores_csv(path: str | Path, rows: list[tuple[str, list[GradeReport]]]) -> Path:
    """One CSV for a class: ``student``, ``sandbox`` (the isolation mode; ``none (INSECURE)`` for a
    score that does not count), one column ``assignment:test_id`` per graded test, ``total``,
    ``max_score``. ``rows`` holds each student's reports (same assignments, same order, for everyone).
    Written atomically, readable by its owner only."""
    path = Path(path)
    columns: list[str] = []
    for _, reports in rows[:1]:
        for rep in reports:
            columns += [f"{rep.assignment.name}:{r.test.id}" for r in rep.tests]
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["student", "sandbox", *columns, "total", "max_score"])
        for student, reports in rows:
            kinds = sorted({rep.sandbox for rep in reports})
            mode = "+".join(kinds) + (" (INSECURE)" if "none" in kinds else "")
            scores = [f"{r.score:g}" for rep in reports for r in rep.tests]
            total = sum(rep.score for rep in reports)
            top = sum(rep.max_score for rep in reports)
            w.writerow([clean(student, 200), mode, *scores, f"{total:g}", f"{top:g}"])
    return path
