"""The grader's end of a child's record of refused attempts: notes the student's code cannot erase.

The child's audit hook (:mod:`lab.grading.sandbox`) writes each note of a refused attempt to a pipe of
its own the moment the attempt is made, before the student's code goes on, and a mark before each
message it sends on the answer channel. What has reached the pipe is the grader's: clearing lists,
patching functions or closing the pipe in the child takes nothing back. The grader reads the pipe
whenever it waits for an answer, and notes tampering itself, from its side:

* a mark missing (or one too many) when an answer arrives: the pipe was closed or replaced by the
  student's code, so what it tried afterwards may be missing;
* a line that is neither a note nor a mark: the student's code wrote to the pipe.

The notes are best-effort: code that finds the hook's own objects through the garbage collector, or
keeps a copy of the pipe and writes the marks itself, can silence what it does afterwards. They never
change a score: the sandbox stops the attempts, the notes only report them.
"""

from __future__ import annotations

import os

__all__ = ["Records", "MAX_NOTES"]

MAX_NOTES = 8  # distinct notes kept per test
_MAX_LINE = 1024  # a longer line is not the child's
CLOSED = (
    "the record of what the sandbox refused was closed or replaced by your code (tampering is "
    "recorded; what it tried afterwards may be missing here)"
)
WRITTEN = "your code wrote to the sandbox's record of refused attempts (tampering is recorded)"


class Records:
    """Reads the record pipe ``fd`` (non-blocking) into ``notes`` (a list it appends to)."""

    def __init__(self, fd: int, notes: list[str]):
        self.fd = fd
        self.notes = notes
        self.marks: list[int] = []
        self.more = 0  # distinct notes beyond MAX_NOTES
        self._buf = bytearray()
        self._eof = False
        os.set_blocking(fd, False)

    def _add(self, text: str) -> None:
        if text in self.notes:
            return
        if len(self.notes) < MAX_NOTES:
            self.notes.append(text)
        else:
            self.more += 1

    def waiting(self) -> tuple[int, ...]:
        """The pipe, to wait on with ``select``, until the child's end is closed."""
        return () if self._eof else (self.fd,)

    def pump(self) -> None:
        """Read what is in the pipe now and take every complete line."""
        while not self._eof:
            try:
                chunk = os.read(self.fd, 1 << 16)
            except BlockingIOError:
                break
            except OSError:
                chunk = b""
            if not chunk:
                self._eof = True
                break
            self._buf += chunk
            self._lines()

    def _lines(self) -> None:
        while True:
            end = self._buf.find(b"\n")
            if end < 0:
                if len(self._buf) > _MAX_LINE:
                    self._buf.clear()
                    self._add(WRITTEN)
                return
            line = bytes(self._buf[:end])
            del self._buf[: end + 1]
            if line.startswith(b"N") and len(line) <= _MAX_LINE:
                self._add(line[1:].decode("utf-8", "replace"))
            elif line.startswith(b"M") and line[1:].isdigit() and len(line) < 24:
                self.marks.append(int(line[1:]))
            else:
                self._add(WRITTEN)

    def after_message(self, k: int) -> None:
        """The ``k``-th message (0: the import's) has arrived: its mark, written before it, must have,
        and no later one."""
        self.pump()
        if self.marks != list(range(k + 1)):
            self._add(CLOSED)
            self.marks = list(range(k + 1))  # said once; the next messages are judged afresh

    def finish(self) -> None:
        """Once the child is gone: read the rest, then close the pipe."""
        self.pump()
        if self._buf:  # a line without its end: not the child's
            self._buf.clear()
            self._add(WRITTEN)
        if self.more:
            self.notes.append(f"... and {self.more} more refused attempt(s)")
            self.more = 0
        try:
            os.close(self.fd)
        except OSError:
            pass
