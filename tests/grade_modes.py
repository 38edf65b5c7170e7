"""The isolation modes this machine has, for the grading tests (issue 47).

A grading test asks for a mode with a fixture: ``grading_mode`` runs it once in each of bubblewrap
(``bwrap``) and the uid mode (``uid``), ``any_mode`` once in the strongest mode there is. A mode the
machine lacks skips the test with one line naming what to install, except that under CI
(``CI=true``) a missing bubblewrap fails instead, and so does a uid mode that does not work as root on
Linux: CI must prove both.
"""

from __future__ import annotations

import os
import sys

import pytest

from lab.grading.isolation import SandboxUnavailable, _find, find_sandbox

__all__ = ["grading_mode", "any_mode"]

WHAT_TO_INSTALL = {
    "bwrap": "install bubblewrap (apt-get install bubblewrap, dnf install bubblewrap; Linux only)",
    "uid": "run the tests as root on Linux (the uid mode is for a root grader, as on Gradescope)",
}


def _ci() -> bool:
    return os.environ.get("CI", "").lower() == "true"


def mode_missing(mode: str) -> str | None:
    """None when ``mode`` (``bwrap`` or ``uid``) works here, else why not."""
    try:
        _find(mode)
    except SandboxUnavailable as e:
        return str(e)
    return None


def _root_on_linux() -> bool:
    return sys.platform == "linux" and os.geteuid() == 0


def require(mode: str) -> None:
    """Skip unless ``mode`` works on this machine; under CI fail instead for bubblewrap, and for the uid
    mode when the tests run as root on Linux (where it must work: CI proves both)."""
    why = mode_missing(mode)
    if why is None:
        return
    if _ci() and (mode == "bwrap" or _root_on_linux()):
        pytest.fail(f"CI=true and the {mode} isolation mode does not work here: {why}")
    first = why.split(";")[0]
    # as root the uid mode's own reason says what to change (e.g. a Python other users cannot read)
    how = first if "install" in first or (mode == "uid" and _root_on_linux()) else WHAT_TO_INSTALL[mode]
    pytest.skip(f"needs the {mode} isolation mode: {how}")


@pytest.fixture(params=["bwrap", "uid"])
def grading_mode(request, monkeypatch) -> str:
    """Each isolation mode in turn (``LAB_GRADE_SANDBOX``, which ``lab grade`` subprocesses inherit)."""
    require(request.param)
    monkeypatch.setenv("LAB_GRADE_SANDBOX", request.param)
    return request.param


@pytest.fixture
def any_mode(monkeypatch) -> str:
    """The strongest isolation mode this machine has (its kind)."""
    monkeypatch.delenv("LAB_GRADE_SANDBOX", raising=False)
    if _ci():
        require("bwrap")
    try:
        return find_sandbox().kind
    except SandboxUnavailable as e:
        why = str(e)  # as root, the uid mode's reason too: what to change to have it
        if not _root_on_linux():
            why = f"{why.split(';')[0]} (or run as root on Linux: the uid mode)"
        pytest.skip(f"needs an isolation mode for grading: {why}")
