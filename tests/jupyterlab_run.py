"""A real JupyterLab for the notebook tests (tests/test_notebooks.py): a server on a free local
port with its own token and its own Jupyter folders (config, data, runtime, settings, workspaces)
under a temporary folder, and what the tests read back from a notebook run in it through
:class:`browser.Browser`.

The server serves a copy of the notebooks (a run never writes outputs into the checkout) and its
kernels inherit ``LAB_FAST=1`` and ``MPLBACKEND``, as the notebooks' fast mode wants. JupyterLab is
started with ``expose_app_in_browser`` (``window.jupyterapp``), the hook JupyterLab's own UI tests use,
so that the test runs "Run All Cells" as the menu does (the same command) and reads the notebook's
model: every cell's outputs as nbformat JSON.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

__all__ = ["JupyterLab", "NotebookRun", "checkout_copy", "run_notebook"]

#: Settings for the test's JupyterLab: every cell in the page (no windowing: off-screen outputs are
#: rendered too), and nothing fetched from the web (news, update checks).
SETTINGS = {
    "@jupyterlab/notebook-extension/tracker.jupyterlab-settings": {"windowingMode": "none"},
    "@jupyterlab/apputils-extension/notification.jupyterlab-settings": {
        "checkForUpdates": False,
        "fetchNews": "false",
    },
}


class JupyterLab:
    """``jupyter lab`` serving ``root`` (a folder of notebooks), stopped by :meth:`stop` (its process
    group killed) or at the end of a ``with`` block."""

    def __init__(self, root: Path, home: Path, env: dict[str, str], timeout: float = 120.0):
        self.root, self.token = root, secrets.token_hex(16)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}"
        dirs = {k: home / k.lower() for k in ("CONFIG", "DATA", "RUNTIME")}
        settings = home / "settings"
        for name, value in SETTINGS.items():
            (settings / name).parent.mkdir(parents=True, exist_ok=True)
            (settings / name).write_text(json.dumps(value))
        full_env = {
            **os.environ, **env,
            **{f"JUPYTER_{k}_DIR": str(v) for k, v in dirs.items()},
            "JUPYTERLAB_SETTINGS_DIR": str(settings), "JUPYTERLAB_WORKSPACES_DIR": str(home / "workspaces"),
            "JUPYTER_PLATFORM_DIRS": "1",
        }  # fmt: skip
        self._log = open(home / "jupyterlab.log", "wb")  # noqa: SIM115 - closed in stop()
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "jupyterlab", "--no-browser", "--ServerApp.ip=127.0.0.1",
             f"--ServerApp.port={self.port}", "--ServerApp.port_retries=0",
             f"--IdentityProvider.token={self.token}", f"--ServerApp.root_dir={root}",
             "--LabApp.expose_app_in_browser=True", "--LabApp.news_url=",
             "--ServerApp.terminals_enabled=False", "--LabApp.extension_manager=readonly",
             "--ServerApp.allow_root=True"],
            env=full_env, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
        self.log_path = home / "jupyterlab.log"
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.api("GET", "status")
                break
            except OSError:
                if self._proc.poll() is not None or time.monotonic() > deadline:
                    tail = self.log_tail()
                    self.stop()
                    raise RuntimeError(f"jupyter lab did not start: {tail}") from None
                time.sleep(0.3)

    def api(self, method: str, path: str):
        """One call to the server's REST API; its JSON answer (None when empty)."""
        req = urllib.request.Request(f"{self.url}/api/{path}", method=method)
        req.add_header("Authorization", f"token {self.token}")
        with urllib.request.urlopen(req, timeout=30) as r:
            body = r.read()
        return json.loads(body) if body else None

    def page(self, notebook: str) -> str:
        """The URL that opens ``notebook`` (a path under the root) in a fresh workspace."""
        return f"{self.url}/lab/tree/{notebook}?reset&token={self.token}"

    def shut_down_kernels(self) -> None:
        for s in self.api("GET", "sessions") or []:
            self.api("DELETE", f"sessions/{s['id']}")

    def log_tail(self, n: int = 3000) -> str:
        self._log.flush()
        return self.log_path.read_text(errors="replace")[-n:]

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait(timeout=30)
            self._log.close()

    def __enter__(self) -> JupyterLab:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def checkout_copy(repo: Path, dst: Path) -> Path:
    """A stand-in for the checkout at ``dst``: its ``notebooks/`` copied (JupyterLab saves into the
    copy, never into the checkout), every other top-level entry linked (a notebook reads
    ``../hardware/`` as it does in the checkout)."""
    dst.mkdir(parents=True)
    for entry in repo.iterdir():
        if entry.name == "notebooks":
            shutil.copytree(
                entry,
                dst / entry.name,
                ignore=shutil.ignore_patterns(".ipynb_checkpoints", "__pycache__", "out"),
            )
        elif not entry.name.startswith(".") and entry.name != "out":
            (dst / entry.name).symlink_to(entry)
    return dst


# -- a notebook in the page -----------------------------------------------------------------------

#: JavaScript: the notebook panel of the notebook at path NAME (the one the URL opened).
PANEL = (
    "window.jupyterapp && [...jupyterapp.shell.widgets('main')]"
    ".find(w => w.context && w.context.path === NAME)"
)
READY = f"""(() => {{ const p = {PANEL};
  return !!(p && p.content && p.sessionContext && p.sessionContext.session && p.sessionContext.session.kernel
            && p.sessionContext.session.kernel.status === 'idle' && p.content.widgets.length > 0); }})()"""
#: JavaScript: the run's progress, polled (small: no outputs): kernel status, execution counts, cells
#: queued or running ("[*]"), and whether an error output stopped the run.
STATE = f"""(() => {{ const p = {PANEL}; const cells = p.content.widgets.filter(c => c.model.type === 'code');
  const prompt = c => c.node.querySelector('.jp-InputPrompt')?.textContent || '';
  const kinds = c => Array.from({{length: c.model.outputs.length}}, (_, i) => c.model.outputs.get(i).type);
  return JSON.stringify({{
    kernel: p.sessionContext.session ? p.sessionContext.session.kernel.status : 'none',
    counts: cells.map(c => c.model.executionCount),
    running: cells.filter(c => prompt(c).includes('[*]')).length,
    error: cells.some(c => kinds(c).includes('error')) }}); }})()"""
#: JavaScript: the finished run: every code cell's source and outputs (nbformat JSON).
CELLS = f"""(() => {{ const p = {PANEL}; const cells = p.content.widgets.filter(c => c.model.type === 'code');
  return JSON.stringify({{ sources: cells.map(c => c.model.sharedModel.getSource()),
                          outputs: cells.map(c => c.model.outputs.toJSON()) }}); }})()"""
#: JavaScript: how the outputs look on the page: widget views, their failures, 3D view frames.
RENDERED = """(() => {
  const nodes = [...document.querySelectorAll('.jp-Notebook .jp-OutputArea-output')];
  const text = nodes.map(n => n.textContent).join('\\n');
  return JSON.stringify({
    widgets_drawn: nodes.filter(n => n.querySelector(':scope > .jupyter-widgets')).length,
    loading: (text.match(/Loading widget\\.\\.\\./g) || []).length,
    widget_errors: (text.match(/Error displaying widget[^\\n]*/g) || []),
    frames: document.querySelectorAll('.jp-Notebook .jp-OutputArea-output iframe').length }); })()"""


class NotebookRun:
    """What one notebook's run in JupyterLab left: per code cell its source, execution count and
    outputs (nbformat JSON), how the page shows them, and the 3D views' pictures."""

    def __init__(self, state: dict, rendered: dict, views: list, wall_s: float):
        self.sources, self.counts, self.outputs = state["sources"], state["counts"], state["outputs"]
        self.rendered, self.views, self.wall_s = rendered, views, wall_s

    def errors(self) -> list[str]:
        """Every error output: the cell's first line, the exception and its message."""
        return [
            f"cell [{n}] {src.splitlines()[0] if src else ''!r}: {o['ename']}: {o['evalue']}"
            for src, n, outs in zip(self.sources, self.counts, self.outputs, strict=True)
            for o in outs
            if o["output_type"] == "error"
        ]

    def stderr(self) -> list[str]:
        """Every text the cells wrote to stderr (warnings, the library's log lines)."""
        return [
            "".join(o["text"]) if isinstance(o["text"], list) else o["text"]
            for outs in self.outputs
            for o in outs
            if o["output_type"] == "stream" and o["name"] == "stderr"
        ]

    def widget_outputs(self) -> int:
        return sum(
            "application/vnd.jupyter.widget-view+json" in o.get("data", {})
            for outs in self.outputs
            for o in outs
        )

    def view_outputs(self) -> int:
        """HTML outputs holding a 3D view page (lab.viz.view3d.show_page: an iframe of the page)."""
        return sum(
            "<iframe srcdoc=" in "".join(o.get("data", {}).get("text/html", ""))
            for outs in self.outputs
            for o in outs
        )


def run_notebook(b, lab: JupyterLab, name: str, timeout: float, shots: Path) -> NotebookRun:
    """Open ``name`` in the page, run all its cells, wait until the kernel is idle with no cell queued,
    then read the run back (and look at each 3D view: see :func:`look_at_views`)."""
    t0 = time.monotonic()
    b.open(lab.page(name), timeout=120)
    js = {
        k: v.replace("NAME", json.dumps(name))
        for k, v in (("ready", READY), ("state", STATE), ("cells", CELLS))
    }
    b.wait_for(js["ready"], 120, what=f"{name} open with an idle kernel")
    # the menu's Run > Run All Cells: the command, on this notebook made the current one
    panel = PANEL.replace("NAME", json.dumps(name))
    b.evaluate(f"(p => {{ jupyterapp.shell.activateById(p.id); return 1 }})({panel})")
    b.evaluate("jupyterapp.commands.execute('notebook:run-all-cells')")
    deadline = time.monotonic() + timeout
    settled = 0
    while True:
        time.sleep(0.5)
        state = json.loads(b.evaluate(js["state"]))
        done = state["kernel"] == "idle" and state["running"] == 0
        done = done and (state["error"] or all(c is not None for c in state["counts"]))
        settled = settled + 1 if done else 0
        if settled >= 3:  # idle and nothing queued for three polls in a row
            break
        if time.monotonic() > deadline:
            raise TimeoutError(
                f"{name}: not done after {timeout} s: kernel {state['kernel']}, counts {state['counts']}"
            )
    wall = time.monotonic() - t0
    state.update(json.loads(b.evaluate(js["cells"])))
    views = look_at_views(b, name, shots)
    rendered = json.loads(b.evaluate(RENDERED))
    b.screenshot(path=shots / f"notebook_{Path(name).stem}.png")
    return NotebookRun(state, rendered, views, wall)


def look_at_views(b, name: str, shots: Path) -> list[dict]:
    """Each 3D view in the notebook's outputs, scrolled into sight and drawn: its picture's pixel
    spread (a blank canvas has none), kept as a PNG."""
    n = b.evaluate("document.querySelectorAll('.jp-Notebook .jp-OutputArea-output iframe').length")
    views = []
    for k in range(n):
        frame = f"document.querySelectorAll('.jp-Notebook .jp-OutputArea-output iframe')[{k}]"
        b.evaluate(f"{frame}.scrollIntoView({{block: 'center'}})")
        b.wait_for(
            f"(d => !!(d && d.querySelector('canvas') && d.querySelector('.mantine-NumberInput-input')))"
            f"({frame}.contentDocument)",
            120,
            what=f"{name}: 3D view {k} drawn",
        )
        doc = f"{frame}.contentDocument"
        b.evaluate(f"{doc}.querySelectorAll('.mantine-Notification-closeButton').forEach(e => e.click())")
        # pause at the last step (the recording loops otherwise): a time past the end in its time box
        b.evaluate(
            f"(i => {{ i.focus(); i.select(); return 1 }})({doc}.querySelector('.mantine-NumberInput-input'))"
        )
        b.send("Input.insertText", {"text": "99999"})
        rect = json.loads(b.evaluate(f"JSON.stringify({frame}.getBoundingClientRect())"))
        img = b.settled_screenshot(rect, path=shots / f"notebook_{Path(name).stem}_view{k}.png", timeout=120)
        views.append({"std": float(img.std()), "size": img.shape[:2]})
    return views
