"""The profile benchmark's step clock (benchmarks/_common.py, benchmarks/bench_profile.py): each
wrapped call's own time, the originals put back, and the volume unchanged by the timing."""

from __future__ import annotations

import time
import types

import numpy as np
import pytest

import npmrf3d
from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def bp():
    return benchmark_module("bench_profile")


def test_clock_takes_each_call_own_time_and_puts_the_originals_back(bp):
    box = types.SimpleNamespace()

    def inner():
        time.sleep(0.02)
        return 3

    def outer():
        time.sleep(0.01)
        return box.inner() + 1

    class Owner:
        @classmethod
        def make(cls):
            return cls.__name__

    box.inner, box.outer = inner, outer
    clock = bp.StepClock()
    with clock.patch([(box, "inner", "in"), (box, "outer", "out"), (Owner, "make", "cls")]):
        clock.group = 7
        assert box.outer() == 4 and box.outer() == 4
        assert Owner.make() == "Owner"
    assert box.inner is inner and box.outer is outer and Owner.make() == "Owner"
    assert clock.calls == {(7, "in"): 2, (7, "out"): 2, (7, "cls"): 1}
    assert 0.04 <= clock.wall[(7, "in")] < 0.2
    assert 0.02 <= clock.wall[(7, "out")] < clock.wall[(7, "in")]  # without the inner calls' 0.04 s


def test_profiled_run_is_bit_identical_and_its_split_adds_up(bp):
    image = bp.exemplar()
    plain = npmrf3d.synthesize(image, size=32, levels=2, rng=0).volume
    clock = bp.StepClock()
    with clock.patch(bp.targets(clock)):
        t0, c0 = time.perf_counter(), time.process_time()
        result = npmrf3d.synthesize(image, size=32, levels=2, rng=0)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert np.array_equal(result.volume, plain)
    clock.level_seconds = {int(k.split("_")[1]): v for k, v in result.timings.items() if k.startswith("level_")}
    table = bp.split(wall, cpu, clock)
    assert set(table) == {None, 0, 1}
    for level in (0, 1):
        assert table[level][bp.SEARCH][0] > 0 and table[level][bp.SOLVE][0] > 0
        assert table[level][bp.REST][0] >= -1e-3
    assert sum(w for steps in table.values() for w, _ in steps.values()) == pytest.approx(wall)
    floors = bp.floors(result.stats, [0, 1])
    assert floors[0][bp.SEARCH] > floors[1][bp.SEARCH] > 0 and floors[0][bp.SOLVE] > 0
