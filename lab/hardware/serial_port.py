"""Opening serial ports with errors a student can act on.

Both drivers open their device through :func:`open_port`, which wraps ``serial.serial_for_url`` (so a
``socket://host:port`` URL works as well as ``/dev/ttyUSB0``), locks the port for exclusive use, and
turns pyserial's errors into one clear line: which device, which port, what is plugged in instead, and
what to do.

pyserial reports an unplugged device as ``SerialException`` (an ``OSError``) from ``read``/``write``
and as a plain ``OSError`` (EIO) from ``in_waiting``; the drivers therefore catch ``OSError``.
"""

from __future__ import annotations

import errno

import serial
import serial.tools.list_ports

from lab.errors import ConnectionLost, LabError

__all__ = ["PortUnavailable", "available_ports", "open_port"]


class PortUnavailable(LabError, ConnectionError):
    """A serial port could not be opened (missing, busy, or not a serial device); nothing was sent."""


def available_ports() -> list[str]:
    """Serial ports the operating system lists right now (``serial.tools.list_ports``)."""
    try:
        return sorted(p.device for p in serial.tools.list_ports.comports())
    except Exception:  # listing is advisory; never let it hide the real error
        return []


def _ports_hint() -> str:
    ports = available_ports()
    return "available ports: " + (", ".join(ports) if ports else "none found")


def open_port(
    url: str,
    baudrate: int,
    *,
    what: str,
    timeout: float = 0.02,
    write_timeout: float = 0.5,
    config_key: str = "port",
) -> serial.SerialBase:
    """Open ``url`` exclusively at ``baudrate`` 8N1 without flow control.

    Parameters
    ----------
    url : str
        A device path (``/dev/ttyUSB0``) or a pyserial URL (``socket://host:4000``).
    what : str
        The device's name for error messages ("PTU-D46", "Create 2").
    timeout, write_timeout : float [s]
        pyserial's read and write timeouts; the drivers read in short slices and keep their own deadlines.

    Raises
    ------
    PortUnavailable
        Missing path, port busy (another program or notebook kernel holds it), or permission denied.
    """
    if not isinstance(url, str) or not url:
        raise PortUnavailable(f"{what}: no serial port configured; set [{config_key}] to e.g. /dev/ttyUSB0")
    try:
        return serial.serial_for_url(
            url,
            baudrate=baudrate,
            bytesize=serial.EIGHTBITS,
            parity=serial.PARITY_NONE,
            stopbits=serial.STOPBITS_ONE,
            timeout=timeout,
            write_timeout=write_timeout,
            exclusive=True,
        )
    except (serial.SerialException, OSError, ValueError) as e:
        code = getattr(e, "errno", None)
        if code == errno.ENOENT or "No such file" in str(e):
            raise PortUnavailable(
                f"{what}: port {url} not found ({_ports_hint()}); check the cable or {config_key}"
            ) from e
        if code in (errno.EAGAIN, errno.EBUSY) or "exclusively lock" in str(e):
            raise PortUnavailable(
                f"{what}: port {url} is in use by another program (another notebook kernel?); close it first"
            ) from e
        if code == errno.EACCES:
            raise PortUnavailable(
                f"{what}: no permission to open {url}; add yourself to the 'dialout' group and log in again"
            ) from e
        raise PortUnavailable(f"{what}: cannot open {url}: {e} ({_ports_hint()})") from e


def lost(what: str, url: str, err: BaseException, consequence: str) -> ConnectionLost:
    """The error raised when a device goes away mid-session; ``consequence`` says what that device
    does now that nothing can reach it (e.g. a base keeps its last wheel speeds)."""
    return ConnectionLost(
        f"{what} on {url} went away ({err}); {consequence}. Plug it back in and call reconnect()"
    )
