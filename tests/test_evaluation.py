"""The report split and the Wilson intervals, against SciPy's binomial test."""

import pytest
from scipy.stats import binomtest

from lab.errors import ConfigError
from lab.evaluation import REPORT_SEEDS_START, report_seeds, split_of, wilson_interval


@pytest.mark.parametrize("k, n", [(0, 5), (3, 7), (97, 100), (100, 100), (39, 40), (1, 1)])
def test_wilson_interval_matches_scipy(k, n):
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert wilson_interval(k, n) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_the_splits_are_named_and_far_apart():
    seeds = report_seeds(25)
    assert seeds[0] == REPORT_SEEDS_START == 100000 and len(seeds) == 25
    assert split_of(seeds) == "report"
    assert split_of(range(20)) == "tuning"
    assert split_of([3, 100001]) == "mixed"


def test_bad_counts_are_refused():
    with pytest.raises(ConfigError, match="0 <= k <= n and n >= 1, got k=5, n=4"):
        wilson_interval(5, 4)
    with pytest.raises(ConfigError, match="positive integer"):
        report_seeds(0)


def test_seed_lists_parse_and_bad_ones_are_one_clear_line():
    from lab.evaluation import parse_seeds

    assert parse_seeds("100000-100003,7") == [100000, 100001, 100002, 100003, 7]
    assert parse_seeds("0-3,5") == [0, 1, 2, 3, 5] and parse_seeds("4") == [4]
    with pytest.raises(ConfigError, match="seeds must look like 100000-100024 or 0,3,5, got 'x'"):
        parse_seeds("1,x")
    with pytest.raises(ConfigError, match="runs backwards"):
        parse_seeds("9-3")
