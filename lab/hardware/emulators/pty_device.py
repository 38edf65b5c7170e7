"""The byte-level base of the device emulators: a device on a pseudo-terminal with its own thread and clock.

Each emulator owns a pty pair (``os.openpty()``, raw mode) and a thread that ``select``s on the master
side and on a stop pipe, so :meth:`PtyDevice.close` never hangs: the thread is woken and joined *before*
the master fd is closed (closing it while a thread blocks in ``os.read`` does not hang the pty up, see the
reference notes section 6.3). The drivers open the slave side with real pyserial I/O; with ``link`` set,
a stable symlink points at the current slave, and :meth:`PtyDevice.replug` re-points it at a fresh pty, as
a USB adapter that reappears under the same name.

Each emulator keeps its own clock (:meth:`PtyDevice.now`, seconds since it was created). Everything the
host sends is logged with the emulator's time, so a test can measure when a command arrived.

Fault switches every device has: ``silent``, ``delay_s``, :meth:`~PtyDevice.inject` (garbage bytes),
:meth:`~PtyDevice.unplug` / :meth:`~PtyDevice.replug`.
"""

from __future__ import annotations

import heapq
import os
import select
import threading
import time
import tty

__all__ = ["PtyDevice"]


class PtyDevice:
    """A byte-level device on a pty: subclasses implement :meth:`on_bytes` and :meth:`on_tick`.

    Parameters
    ----------
    link : path, optional
        A symlink kept pointing at the current slave (``port`` then returns it).
    name : str
    """

    tick_s = 0.005

    def __init__(self, link: str | os.PathLike | None = None, name: str = "device"):
        self.name = name
        self.link = str(link) if link else None
        self._t0 = time.monotonic()
        self._lock = threading.RLock()
        self._out: list[tuple[float, int, bytes]] = []
        self._seq = 0
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name = ""
        self._thread: threading.Thread | None = None
        self._stop_r: int | None = None
        self._stop_w: int | None = None
        self.plugged = False
        self.silent = False
        self.delay_s = 0.0
        self.rx_log: list[tuple[float, bytes]] = []
        self.dropped_bytes = 0
        #: how much later than it asked for the device thread got the CPU back, at most [s] (since reset
        #: to 0 by a test): the emulator's clock stamps what it receives when it runs, so on a loaded
        #: machine its timings include this; a test can tell a late host from a late emulator with it
        self.max_lateness_s = 0.0

    # --- clock and port -------------------------------------------------------------------------
    def now(self) -> float:
        """The emulator's clock [s] (monotonic, zero when it was created)."""
        return time.monotonic() - self._t0

    @property
    def port(self) -> str:
        return self.link or self._slave_name

    @property
    def slave_name(self) -> str:
        """The pty's device file (``/dev/pts/N``) the host opens; ``""`` before :meth:`start`."""
        return self._slave_name

    @property
    def rx_bytes(self) -> bytes:
        """Everything the host sent since start (or since :meth:`clear_log`)."""
        with self._lock:
            return b"".join(d for _, d in self.rx_log)

    def clear_log(self) -> None:
        with self._lock:
            self.rx_log.clear()

    # --- lifecycle ------------------------------------------------------------------------------
    def start(self):
        """Create the pty and start the device thread; returns self."""
        with self._lock:
            if not self.plugged:
                self._open()
        return self

    def _open(self) -> None:
        m, s = os.openpty()
        tty.setraw(m)
        tty.setraw(s)
        os.set_blocking(m, False)  # a host that stops reading must never block the device thread
        self._master, self._slave = m, s
        self._slave_name = os.ttyname(s)
        if self.link:
            tmp = self.link + ".tmp"
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(self._slave_name, tmp)
            os.replace(tmp, self.link)
        self._stop_r, self._stop_w = os.pipe()
        self.plugged = True
        self._thread = threading.Thread(target=self._run, name=f"{self.name} emulator", daemon=True)
        self._thread.start()

    def _stop_thread(self) -> None:
        t = self._thread
        if t is not None:
            os.write(self._stop_w, b"x")
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._thread = None
        for fd in (self._stop_r, self._stop_w):
            if fd is not None:
                os.close(fd)
        self._stop_r = self._stop_w = None

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self.link and os.path.islink(self.link):
            os.unlink(self.link)
        self.plugged = False
        with self._lock:
            self._out.clear()

    def unplug(self) -> None:
        """Pull the cable: stop the thread, then close the pty (the host sees EIO) and remove the link."""
        if not self.plugged:
            return
        self._stop_thread()
        self._close_fds()
        self.on_unplug()

    def replug(self) -> None:
        """Plug back in: a fresh pty under the same link; the device keeps its state (it stayed powered)."""
        if self.plugged:
            return
        with self._lock:
            self._open()

    def close(self) -> None:
        """Stop and release everything. Safe to call twice."""
        if self._thread is not None:
            self._stop_thread()
        if self._master is not None or self.plugged:
            self._close_fds()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()
        return False

    # --- I/O --------------------------------------------------------------------------------------
    def send(self, data: bytes, extra_delay: float = 0.0) -> None:
        """Queue bytes for the host, after ``delay_s + extra_delay`` on the device clock."""
        with self._lock:
            if self.silent or not data:
                return
            self._seq += 1
            heapq.heappush(self._out, (self.now() + self.delay_s + extra_delay, self._seq, bytes(data)))

    def inject(self, data: bytes) -> None:
        """Send raw bytes now (garbage on the line), whatever the protocol state."""
        self.send(data)

    def _flush_due(self) -> None:
        now = self.now()
        while self._out and self._out[0][0] <= now:
            _, _, data = heapq.heappop(self._out)
            try:
                n = os.write(self._master, data)
                self.dropped_bytes += len(data) - n
            except OSError:  # EAGAIN (host not reading: a UART would overrun too) or EIO
                self.dropped_bytes += len(data)

    def _run(self) -> None:
        m, sr = self._master, self._stop_r
        while True:
            with self._lock:
                timeout = self.tick_s
                if self._out:
                    timeout = min(timeout, max(0.0, self._out[0][0] - self.now()))
            t_ask = time.monotonic()
            r, _, _ = select.select([m, sr], [], [], timeout)
            if sr in r:
                return
            if not r:  # woken by the timeout: by how much late
                self.max_lateness_s = max(self.max_lateness_s, time.monotonic() - t_ask - timeout)
            if m in r:
                try:
                    data = os.read(m, 4096)
                except BlockingIOError:
                    data = b""
                except OSError:  # EIO: nobody has the slave open (we keep it open, so rare)
                    data = b""
                    time.sleep(self.tick_s)
                if data:
                    with self._lock:
                        self.rx_log.append((self.now(), data))
                        if not self.silent:
                            self.on_bytes(data)
            with self._lock:
                self.on_tick(self.now())
                self._flush_due()

    # --- subclass hooks ---------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:  # pragma: no cover - abstract
        pass

    def on_tick(self, now: float) -> None:  # pragma: no cover - abstract
        pass

    def on_unplug(self) -> None:
        pass
