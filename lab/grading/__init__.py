"""Graded assignments: an autograder that runs each test's student code in a separate, sandboxed process.

* :mod:`lab.grading.assignments`: where the assignments are and what each is made of;
* :mod:`lab.grading.suite`: how graded tests are written (points, visibility, checks with messages);
* :mod:`lab.grading.runner`: grading one submission (the isolation design is in its docstring);
* :mod:`lab.grading.isolation`: the isolation modes each child runs in (bubblewrap, or a throwaway uid
  where namespaces are forbidden); :mod:`lab.grading.seccomp`: the system calls a child may not make;
  :mod:`lab.grading.sandbox_check`: ``lab grade --check-sandbox``;
* :mod:`lab.grading.sandbox`: the child process and its wire format;
* :mod:`lab.grading.rules`: an assignment's import rules, its oracles, a submission the grader could import;
* :mod:`lab.grading.records`: the record of refused attempts, read from a pipe as they happen;
* :mod:`lab.grading.report`: Gradescope's results.json, the terminal summary, the class CSV;
* :mod:`lab.grading.release`: the student release (solution blocks stripped, graded tests left out);
* :mod:`lab.grading.gradescope`: the Gradescope autograder bundle (``lab assignments gradescope``);
* :mod:`lab.grading.selfcheck`: a student's check with the public tests (``lab check``);
* :mod:`lab.grading.cli`: ``lab grade`` and ``lab assignments``.
"""

from lab.grading.assignments import Assignment, assignments_dir, get_assignment, list_assignments
from lab.grading.report import GradeReport, TestResult, write_scores_csv
from lab.grading.runner import grade_submission

__all__ = [
    "Assignment",
    "GradeReport",
    "TestResult",
    "assignments_dir",
    "get_assignment",
    "grade_submission",
    "list_assignments",
    "write_scores_csv",
]
