"""How results are reported: the seed splits, and success rates with their Wilson 95 % intervals.

**Tune on one split, report on another.** Seeds below :data:`TUNING_SEEDS_END` (1000) are for tuning
parameters; evaluations report on seeds from :data:`REPORT_SEEDS_START` on, far above them, so that a
reported figure never comes from the seeds it was tuned on. The evaluation scripts default to
the report split and print the split they used (:func:`split_of`).

**Success rates** are given with the Wilson score interval (:func:`wilson_interval`), which stays
inside [0, 1] and keeps its coverage for rates near 0 or 1 and small counts, where the normal
approximation does not.

**Spent seeds.** A report seed that was looked at to decide anything, or whose figures were reported, is
spent: a figure measured on it again is no fresh evidence. The ledger of spent seeds is a file shipped
in the package, ``lab/data/spent_seeds.toml`` (:func:`ledger_path`): one :class:`SpentSeeds` entry per
decision, with the range, what it decided, the runs that used it, and its date, commit and source.
:func:`check_report_seeds` refuses a spent seed for reporting unless it is allowed explicitly (the
evaluations' ``--allow-spent-seeds``, and their report then says "on spent seeds"); seeds below
:data:`TUNING_SEEDS_END` are never refused. :func:`fresh_report_seeds` gives the evaluations' defaults,
and :func:`record_spending` (``lab eval spend``) appends a new entry.
"""

from __future__ import annotations

import datetime
import json
import math
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from lab.errors import ConfigError

__all__ = [
    "ALLOW_SPENT_FLAG",
    "REPORT_SEEDS_START",
    "TUNING_SEEDS_END",
    "SpentSeeds",
    "check_report_seeds",
    "fresh_report_seeds",
    "is_spent",
    "ledger_path",
    "load_ledger",
    "parse_seeds",
    "record_spending",
    "report_seeds",
    "seed_ranges_text",
    "spent_among",
    "spent_note",
    "spent_seeds",
    "split_of",
    "wilson_interval",
]

TUNING_SEEDS_END = 1000  #: the tuning split is the seeds below this
REPORT_SEEDS_START = 100000  #: the report split starts here
FRESH_BLOCK = 100  #: fresh report seeds start on a multiple of this above the split's start
ALLOW_SPENT_FLAG = "--allow-spent-seeds"  #: the evaluations' flag that reports on spent seeds anyway


def report_seeds(n: int, start: int = REPORT_SEEDS_START) -> list[int]:
    """The first ``n`` seeds of the report split."""
    if int(n) != n or n < 1:
        raise ConfigError(f"the number of report seeds must be a positive integer, got {n!r}")
    return list(range(start, start + int(n)))


def parse_seeds(text: str) -> list[int]:
    """``"3-6,9"`` -> ``[3, 4, 5, 6, 9]``: the evaluation scripts' ``--seeds`` (ranges ``A-B`` and single
    numbers, comma-separated).

    Raises
    ------
    ConfigError
        A part that is neither a number nor ``A-B`` with A <= B.
    """
    out: list[int] = []
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        a, sep, b = part.partition("-")
        try:
            lo, hi = (int(a), int(b)) if sep else (int(a), int(a))
        except ValueError:
            msg = f"seeds must look like 100000-100024 or 0,3,5, got {part!r} in {text!r}"
            raise ConfigError(msg) from None
        if hi < lo:
            raise ConfigError(f"seed range {part!r} runs backwards (write {hi}-{lo})")
        out += range(lo, hi + 1)
    return out


def split_of(seeds: Iterable[int]) -> str:
    """``"report"`` (every seed >= :data:`REPORT_SEEDS_START`), ``"tuning"`` (every seed below
    :data:`TUNING_SEEDS_END`) or ``"mixed"``: what a figure measured on ``seeds`` may be called."""
    seeds = list(seeds)
    if not seeds:
        raise ConfigError("no seeds")
    if all(s >= REPORT_SEEDS_START for s in seeds):
        return "report"
    if all(0 <= s < TUNING_SEEDS_END for s in seeds):
        return "tuning"
    return "mixed"


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    r"""The Wilson score interval of a success rate ``k / n`` (95 % for the default ``z``).

    .. math::

        \frac{\hat p + \frac{z^2}{2n} \pm z \sqrt{\frac{\hat p (1 - \hat p)}{n} + \frac{z^2}{4n^2}}}
             {1 + \frac{z^2}{n}}, \qquad \hat p = k / n

    Raises
    ------
    ConfigError
        ``n`` < 1, or ``k`` outside 0..n.
    """
    if int(n) != n or n < 1 or int(k) != k or not 0 <= k <= n:
        raise ConfigError(f"a success rate needs 0 <= k <= n and n >= 1, got k={k!r}, n={n!r}")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


# -- the ledger of spent seeds -------------------------------------------------------------------------

_REQUIRED = ("first", "last", "decided", "runs")
_OPTIONAL = ("date", "commit", "source")


@dataclass(frozen=True)
class SpentSeeds:
    """One entry of the ledger: the report seeds ``first``..``last`` (inclusive) and what looking at
    them decided (``decided``), the runs or commands that used them (``runs``), and, when known, the
    date (``YYYY-MM-DD``), the commit and where it is written down (``source``)."""

    first: int
    last: int
    decided: str
    runs: tuple[str, ...]
    date: str | None = None
    commit: str | None = None
    source: str | None = None

    def __contains__(self, seed) -> bool:
        return self.first <= seed <= self.last

    @property
    def seeds(self) -> range:
        return range(self.first, self.last + 1)

    @property
    def label(self) -> str:
        """``"A-B"``, or ``"A"`` for one seed."""
        return str(self.first) if self.first == self.last else f"{self.first}-{self.last}"


def ledger_path() -> Path:
    """The ledger shipped in the package: ``lab/data/spent_seeds.toml`` (found through
    :mod:`importlib.resources`, so an installed package reads its own copy)."""
    return Path(str(resources.files("lab") / "data" / "spent_seeds.toml"))


def _entry(raw, where: str) -> SpentSeeds:
    """One ``[[spent]]`` table, checked; every problem is a :class:`ConfigError` naming ``where``."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{where} is not a table")
    missing = [k for k in _REQUIRED if k not in raw]
    unknown = sorted(set(raw) - set(_REQUIRED) - set(_OPTIONAL))
    if missing or unknown:
        what = f"lacks {', '.join(missing)}" if missing else f"has unknown field(s) {', '.join(unknown)}"
        raise ConfigError(f"{where} {what}; fields: {', '.join(_REQUIRED + _OPTIONAL)}")
    first, last = raw["first"], raw["last"]
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (first, last)):
        raise ConfigError(f"{where}: first and last must be integers, got {first!r} and {last!r}")
    if first < REPORT_SEEDS_START:
        raise ConfigError(f"{where}: {first} is not a report seed (they start at {REPORT_SEEDS_START})")
    if last < first:
        raise ConfigError(f"{where}: the range {first}-{last} runs backwards")
    if not isinstance(raw["decided"], str) or not raw["decided"].strip():
        raise ConfigError(f"{where}: 'decided' must say what the seeds decided, got {raw['decided']!r}")
    runs = raw["runs"]
    if not isinstance(runs, list) or not runs or not all(isinstance(r, str) and r.strip() for r in runs):
        raise ConfigError(f"{where}: 'runs' must be a list of names like [\"search\"], got {runs!r}")
    extra = {k: raw.get(k) for k in _OPTIONAL}
    if isinstance(extra["date"], datetime.date):
        extra["date"] = extra["date"].isoformat()
    for k, v in extra.items():
        if v is not None and not isinstance(v, str):
            raise ConfigError(f"{where}: {k!r} must be a string, got {v!r}")
    if extra["date"] is not None:
        try:
            datetime.date.fromisoformat(extra["date"])
        except ValueError:
            raise ConfigError(f"{where}: date must be YYYY-MM-DD, got {extra['date']!r}") from None
    return SpentSeeds(first, last, raw["decided"].strip(), tuple(r.strip() for r in runs), **extra)


def _parse_ledger(text: str, path: Path) -> tuple[SpentSeeds, ...]:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"seed ledger {path} is not valid TOML: {e}") from None
    unknown = sorted(set(data) - {"spent"})
    if unknown:
        raise ConfigError(f"seed ledger {path}: unknown table(s) {', '.join(unknown)}; it holds [[spent]]")
    entries = data.get("spent", [])
    if not isinstance(entries, list):
        raise ConfigError(f"seed ledger {path}: 'spent' must be an array of tables ([[spent]])")
    return tuple(_entry(raw, f"seed ledger {path}: [[spent]] entry {i + 1}") for i, raw in enumerate(entries))


def load_ledger(path: str | Path | None = None) -> tuple[SpentSeeds, ...]:
    """The entries of the ledger at ``path`` (default: :func:`ledger_path`), in file order.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or an entry is malformed: one line naming the file, the entry
        and what is wrong.
    """
    path = ledger_path() if path is None else Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"seed ledger {path} does not exist") from None
    return _parse_ledger(text, path)


def _entries(ledger) -> tuple[SpentSeeds, ...]:
    """``ledger``: entries already loaded, or a path (``None``: the package's ledger)."""
    if isinstance(ledger, (tuple, list)):
        return tuple(ledger)
    return load_ledger(ledger)


def spent_seeds(ledger=None) -> frozenset[int]:
    """Every seed of every entry of the ledger (a path, entries, or ``None`` for the package's)."""
    return frozenset(s for e in _entries(ledger) for s in e.seeds)


def is_spent(seed: int, ledger=None) -> bool:
    """Whether ``seed`` is in the ledger."""
    return any(seed in e for e in _entries(ledger))


def spent_among(seeds: Iterable[int], ledger=None, run: str | None = None) -> dict[int, SpentSeeds]:
    """The spent seeds among ``seeds``, each with the first ledger entry that holds it (the first one
    whose ``runs`` name ``run``, when there is one)."""
    entries = _entries(ledger)
    out = {}
    for s in sorted(set(seeds)):
        hits = [e for e in entries if s in e]
        if hits:
            out[s] = next((e for e in hits if run in e.runs), hits[0])
    return out


def fresh_report_seeds(n: int, ledger=None) -> list[int]:
    """The evaluations' default seeds: ``n`` consecutive report seeds above every spent one, starting
    on the next multiple of :data:`FRESH_BLOCK` counted from :data:`REPORT_SEEDS_START`.

    Why above every spent seed and not in a gap between two entries: everything the project ever looked
    at lies at or below the highest recorded seed, while a gap may hold seeds that were looked at and
    never written down. Why on a block boundary: each split then has its own block, as the recorded
    ones do, and a range reads as one split.
    """
    entries = _entries(ledger)
    top = max((e.last for e in entries), default=REPORT_SEEDS_START - 1)
    blocks = -(-(top + 1 - REPORT_SEEDS_START) // FRESH_BLOCK)  # ceil
    return report_seeds(n, start=REPORT_SEEDS_START + FRESH_BLOCK * max(0, blocks))


def _ranges(seeds: Iterable[int]) -> list[tuple[int, int]]:
    """Sorted seeds -> their runs of consecutive numbers, ``(first, last)`` each."""
    out: list[tuple[int, int]] = []
    for s in sorted(set(seeds)):
        if out and s == out[-1][1] + 1:
            out[-1] = (out[-1][0], s)
        else:
            out.append((s, s))
    return out


def seed_ranges_text(seeds: Iterable[int]) -> str:
    """``[1, 2, 3, 7]`` -> ``"1-3,7"``: what ``--seeds`` takes (:func:`parse_seeds`)."""
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in _ranges(seeds))


def check_report_seeds(
    seeds: Iterable[int], allow_spent: bool = False, ledger=None, run: str | None = None
) -> dict[int, SpentSeeds]:
    """The spent seeds among ``seeds`` (see :func:`spent_among`; ``run``, e.g. ``"search"``, picks the
    entry the refusal quotes), or a refusal.

    Raises
    ------
    ConfigError
        Some seed is spent and ``allow_spent`` is false: one line naming the first spent seed, what it
        decided, how many of the seeds are spent, the fresh default and :data:`ALLOW_SPENT_FLAG`.
    """
    seeds = list(seeds)
    entries = _entries(ledger)
    spent = spent_among((s for s in seeds if s >= REPORT_SEEDS_START), entries, run)
    if spent and not allow_spent:
        s, e = next(iter(spent.items()))
        fresh = fresh_report_seeds(max(1, len(set(seeds))), entries)
        src = f" ({e.source})" if e.source else ""
        raise ConfigError(
            f"seed {s} is spent: it decided {e.decided}{src}; {len(spent)} of {len(set(seeds))} seeds given "
            f"are in the ledger of spent seeds. Report on fresh seeds (e.g. --seeds "
            f"{seed_ranges_text(fresh)}), or give {ALLOW_SPENT_FLAG} and the report says 'on spent seeds'"
        )
    return spent


def spent_note(spent: dict[int, SpentSeeds], n_seeds: int) -> str:
    """The line a report on spent seeds carries (empty when none is)."""
    if not spent:
        return ""
    s, e = next(iter(spent.items()))
    return (
        f"**On spent seeds:** {len(spent)} of the {n_seeds} seeds ({seed_ranges_text(spent)}) are in the "
        f"ledger of spent seeds, e.g. {s}: {e.decided}. These figures are no fresh evidence."
    )


def _toml_entry(e: SpentSeeds) -> str:
    lines = ["", "[[spent]]", f"first = {e.first}", f"last = {e.last}"]
    lines.append(f"decided = {json.dumps(e.decided, ensure_ascii=False)}")
    lines.append(f"runs = {json.dumps(list(e.runs), ensure_ascii=False)}")
    for k in _OPTIONAL:
        v = getattr(e, k)
        if v is not None:
            lines.append(f"{k} = {json.dumps(v, ensure_ascii=False)}")
    return "\n".join(lines) + "\n"


def record_spending(
    seeds: Iterable[int],
    decided: str,
    runs: Iterable[str],
    path: str | Path | None = None,
    date: str | None = None,
    commit: str | None = None,
    source: str | None = None,
) -> tuple[SpentSeeds, ...]:
    """Append an entry per run of consecutive ``seeds`` to the ledger at ``path`` (default: the
    package's), written through a temporary file and a rename; the new entries.

    Raises
    ------
    ConfigError
        No seeds, a seed below :data:`REPORT_SEEDS_START` (tuning seeds are never spent), or an entry the
        ledger would refuse; the ledger is then left as it was.
    """
    from lab.io import write_text_atomic

    seeds = sorted(set(seeds))
    if not seeds:
        raise ConfigError("no seeds to record")
    low = [s for s in seeds if s < REPORT_SEEDS_START]
    if low:
        raise ConfigError(
            f"seed {low[0]} is not a report seed (they start at {REPORT_SEEDS_START}): only report seeds are "
            "spent"
        )
    path = ledger_path() if path is None else Path(path)
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    extra = {"decided": decided, "runs": list(runs), "date": date or datetime.date.today().isoformat()}
    extra.update({k: v for k, v in (("commit", commit), ("source", source)) if v is not None})
    new = tuple(_entry({"first": a, "last": b, **extra}, f"the new entry {a}-{b}") for a, b in _ranges(seeds))
    text = text.rstrip("\n") + "\n" + "".join(_toml_entry(e) for e in new)
    _parse_ledger(text, path)  # what is written reads back
    write_text_atomic(path, text)
    return new
