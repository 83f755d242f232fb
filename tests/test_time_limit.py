"""The suite's per-test time limit (conftest.time_limit): a hang fails its test."""

import time
from types import SimpleNamespace

import pytest

from tests.conftest import RanPastLimit, time_limit


def test_a_test_past_its_limit_is_stopped_even_if_it_catches_exceptions():
    item = SimpleNamespace(nodeid="t", get_closest_marker=lambda name: SimpleNamespace(args=(0.2,)))
    t0 = time.monotonic()
    with pytest.raises(RanPastLimit, match=r"t: call ran past 0\.2 s"):
        with time_limit(item, "call"):
            try:
                time.sleep(5)
            except Exception:  # noqa: BLE001 - code under test that swallows errors
                pass
    assert time.monotonic() - t0 < 2


def test_a_test_within_its_limit_is_left_alone():
    item = SimpleNamespace(nodeid="t", get_closest_marker=lambda name: None)
    with time_limit(item, "call"):
        time.sleep(0.01)
