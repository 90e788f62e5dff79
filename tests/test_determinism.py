"""The autouse fixtures of tests/conftest.py: every test starts from the same random state and
reads the same wall clock, whatever ran before it on its xdist worker."""

import random
import time

import numpy as np

from .conftest import FIXED_TIME, SEED


def test_global_rngs_start_seeded():
    got = (random.random(), float(np.random.random()))
    random.seed(SEED)
    np.random.seed(SEED)
    assert got == (random.random(), float(np.random.random()))


def test_global_rngs_are_reseeded_per_test():
    # the test above drew from both generators; this one starts where it started
    a, b = random.random(), float(np.random.random())
    random.seed(SEED + 1)
    np.random.seed(SEED + 1)
    assert (a, b) != (random.random(), float(np.random.random()))  # the seed matters
    random.seed(SEED)
    np.random.seed(SEED)
    assert (a, b) == (random.random(), float(np.random.random()))


def test_wall_clock_is_fixed():
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z")  # what rfw.bench.runner writes
    assert stamp == "2027-01-15T08:00:00+0000"
    assert time.strftime("%Y", time.gmtime(0)) == "1970"  # an explicit time is kept
    assert FIXED_TIME.tm_year == 2027
