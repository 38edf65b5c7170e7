"""What the grader accepts from a child and what it lets out: well-formed frames, clean and bounded text.

A child is the student's code: whatever it sends is untrusted. :mod:`lab.grading.sandbox` bounds a
frame's size (checked on its length header, before anything is read) and what decoding may build
(containers, integer digits); this module checks the *shape* of a decoded frame, so that a malformed
one is the student's failed test (:func:`error_info`, :func:`function_names`), never a grader error.

Everything the grader prints or writes (the terminal summary, ``results.json``, the class CSV) passes
:func:`clean` first: control characters (ANSI escape sequences that redraw a terminal, carriage
returns), invisible bidirectional and zero-width characters and unpaired surrogates are written as
escapes (``\\x1b``), and a text longer than its limit is cut with a marker saying how much.
``results.json`` stays under :data:`RESULTS_MAX_BYTES` whatever the submission sent
(:func:`fit_results`).
"""

from __future__ import annotations

import json
import re

__all__ = [
    "clean",
    "error_info",
    "function_names",
    "fit_results",
    "TEST_OUTPUT_CHARS",
    "RESULTS_MAX_BYTES",
]

TEST_OUTPUT_CHARS = 8000  # one test's feedback in results.json and the summary
RESULTS_MAX_BYTES = 1 << 20  # results.json, whatever the submission does
_NAME_CHARS, _MESSAGE_CHARS, _CODE_CHARS, _MAX_WHERE, _MAX_FUNCTIONS = 200, 2000, 300, 4, 200
# C0 and C1 controls but newline and tab, DEL, zero-width and bidirectional controls, BOM, surrogates
_UNSAFE = re.compile(
    "[\x00-\x08\x0b-\x1f\x7f-\x9f\u200b-\u200f\u202a-\u202e\u2060-\u2069\ufeff\ud800-\udfff]"
)


def _escape(m: re.Match) -> str:
    n = ord(m.group())
    return f"\\x{n:02x}" if n < 0x100 else f"\\u{n:04x}"


def _cut(text: str, limit: int) -> str:
    if len(text) <= limit:
        return text
    return text[:limit] + f" ... [{len(text) - limit} more characters not shown]"


def clean(text, limit: int | None = None) -> str:
    """``text`` safe to print or write: unsafe characters escaped, cut to ``limit`` characters (the
    escapes included) with a marker."""
    text = text if isinstance(text, str) else str(text)
    if limit is None:
        return _UNSAFE.sub(_escape, text)
    safe = _UNSAFE.sub(_escape, text[:limit])
    if len(text) <= limit and len(safe) <= limit:
        return safe
    return safe[:limit] + f" ... [{len(text)} characters, cut to {limit}]"


def error_info(info) -> dict:
    """The child's description of an exception, reduced to the fields and types the grader reads
    (``type``, ``message``, ``where``: file lines, ``memory``); anything else in it is dropped."""
    info = info if isinstance(info, dict) else {}

    def text(v, limit: int) -> str:
        return _cut(v, limit) if isinstance(v, str) else ""

    where = []
    raw = info.get("where")
    for w in raw[:_MAX_WHERE] if isinstance(raw, list) else []:
        if isinstance(w, dict) and type(w.get("line")) is int:
            where.append(
                {
                    "line": w["line"],
                    "function": text(w.get("function"), _NAME_CHARS),
                    "code": text(w.get("code"), _CODE_CHARS),
                }
            )
    return {
        "type": text(info.get("type"), _NAME_CHARS) or "Exception",
        "message": text(info.get("message"), _MESSAGE_CHARS),
        "where": where,
        "memory": info.get("memory") is True,
    }


def function_names(names) -> list[str]:
    """The functions a child says its module defines: strings only, at most a few hundred."""
    if not isinstance(names, list):
        return []
    return [n for n in names[:_MAX_FUNCTIONS] if isinstance(n, str) and len(n) <= _NAME_CHARS]


def fit_results(data: dict, max_bytes: int = RESULTS_MAX_BYTES) -> str:
    """``results.json``'s text for ``data`` (Gradescope's dict), under ``max_bytes``: when the tests'
    outputs make it larger, each is cut to an equal share with a marker."""
    text = json.dumps(data, indent=2) + "\n"
    tests = data.get("tests", [])
    share = max_bytes // (2 * max(len(tests), 1))
    while len(text.encode()) > max_bytes and share > 64:
        for t in tests:
            t["output"] = _cut(t["output"], share // 6)  # an escaped character is at most 6 bytes
            extra = t.get("extra_data", {})
            if "refused" in extra:
                extra["refused"] = [_cut(n, 300) for n in extra["refused"][:8]]
        data["output"] = _cut(data.get("output", ""), share // 6)
        top = data.get("extra_data", {})
        if "refused" in top:
            top["refused"] = [_cut(n, 300) for n in top["refused"][:8]]
        text = json.dumps(data, indent=2) + "\n"
        share //= 2
    return text
