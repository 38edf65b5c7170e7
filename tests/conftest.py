"""Test-session set-up: a persistent cache for trained databases so that the suite trains them once.

The cache is keyed by asset hashes and a format version, so a changed texture or parameter rebuilds;
``LAB_CACHE`` set by the caller wins.
"""

import os
from pathlib import Path

if not os.environ.get("LAB_CACHE"):  # unset or empty
    os.environ["LAB_CACHE"] = str(Path(__file__).resolve().parent.parent / ".lab-cache-test")
