"""The tests' headless-Chromium driver (tests/browser.py) does what the browser tests rely on: requests
off this machine fail and are recorded, from the page and from its workers; local ones go through;
console errors and uncaught exceptions are collected; screenshots are the page's pixels; and closing
leaves no Chromium process behind."""

from __future__ import annotations

import http.server
import os
import threading
import time

import numpy as np
import pytest
from browser import Browser, BrowserError, chromium_or_skip, is_local

PAGE = """<html><body style="margin:0;background:rgb(255,0,0)">
<div id="local">waiting</div>
<img src="https://example.com/pixel.png">
<script>
fetch("http://example.org/api").catch(() => 0);
new Worker(URL.createObjectURL(new Blob(['fetch("https://worker.example.net/x").catch(() => 0)'])));
fetch("/hello").then(r => r.text()).then(t => document.getElementById("local").textContent = t);
console.error("an error on purpose");
setTimeout(() => { throw new Error("thrown on purpose"); }, 0);
</script></body></html>"""


def test_is_local_lets_only_this_machine_through():
    assert is_local("http://127.0.0.1:8888/lab") and is_local("http://localhost/x") and is_local("data:,x")
    assert is_local("file:///tmp/a.html") and is_local("blob:http://localhost/1")
    assert not is_local("https://example.com/") and not is_local("http://localhost.example.com/")


@pytest.fixture
def server():
    class Hello(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # the page itself, and what its script fetches from this machine
            self.send_response(200)
            self.send_header("Content-Type", "text/html" if self.path == "/" else "text/plain")
            self.end_headers()
            self.wfile.write(PAGE.encode() if self.path == "/" else b"local ok")

        def log_message(self, *a):
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Hello)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield httpd.server_address[1]
    httpd.shutdown()


def test_external_requests_fail_and_are_recorded_local_ones_pass(server):
    chromium = chromium_or_skip()
    with Browser(size=(320, 200), chromium=chromium) as b:
        b.open(f"http://127.0.0.1:{server}/")
        assert b.wait_for("document.getElementById('local').textContent === 'local ok'", 30)
        deadline = time.monotonic() + 30
        while len(b.blocked) < 3 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert sorted(b.blocked) == [
            "http://example.org/api", "https://example.com/pixel.png", "https://worker.example.net/x"
        ]  # fmt: skip
        assert b.evaluate("6 * 7") == 42
        with pytest.raises(BrowserError, match="nope"):
            b.evaluate("(() => { throw new Error('nope') })()")
        assert any("an error on purpose" in e for e in b.errors)
        assert any("thrown on purpose" in e for e in b.errors)
        img = b.screenshot(clip={"x": 0, "y": 100, "width": 50, "height": 50})
        assert img.shape == (50, 50, 3) and np.all(img == [255, 0, 0])  # the page's red, as RGB
        group = b.pid
    assert living(group) == []  # the whole process group is gone (at most zombies init reaps)


def living(group: int) -> list[int]:
    """The processes of a process group that are not zombies (read from /proc)."""
    found = []
    for d in os.listdir("/proc"):
        try:
            stat = open(f"/proc/{d}/stat").read()
        except (OSError, ValueError):
            continue
        fields = stat.rsplit(")", 1)[-1].split()  # after the command name: state, ppid, pgrp, ...
        if int(fields[2]) == group and fields[0] != "Z":
            found.append(int(d))
    return found
