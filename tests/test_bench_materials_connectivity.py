"""The connectivity columns of the materials benchmark (benchmarks/bench_materials.py):
percolation per axis and both phases' relative diffusivity, judged against the crops."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.analysis import materials
from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def bm():
    return benchmark_module("bench_materials")


def tubes(side: int = 16) -> np.ndarray:
    """Straight square tubes along axis 0 only: a quarter of the cross-section."""
    ind = np.zeros((side, side, side), dtype=bool)
    ind[:, 2:side // 2 - 2, 2:side // 2 - 2] = True
    return ind


def test_percolation_and_both_phases_diffusivity_per_axis(bm):
    ind = tubes()
    stats = bm.statistics(ind, solver="finite-volume")
    assert [stats[k] for k in bm.PERCS] == [1.0, 0.0, 0.0]
    # straight channels along axis 0: the phase's fraction; none across
    assert stats["diff0"] == pytest.approx(ind.mean(), rel=1e-6)
    assert stats["diff1"] == stats["diff2"] == 0.0 and stats["tau1"] == float("inf")
    # the matrix surrounds the tubes: it conducts along every axis, straight along axis 0
    assert stats["odiff0"] == pytest.approx(1.0 - ind.mean(), rel=1e-6)
    assert 0.0 < stats["odiff1"] < 1.0 - ind.mean()
    assert stats["odiff1"] == pytest.approx(materials.relative_diffusivity(~ind, axis=1), rel=1e-9)


def test_a_volume_missing_an_axis_the_crops_connect_is_outside(bm):
    assert bm.percolation_verdict([1.0, 1.0, 1.0], [1.0, 1.0, 0.8]) == 0.0
    assert bm.percolation_verdict([1.0, 0.0, 0.0], [1.0, 1.0, 0.2]) == pytest.approx(0.5)
    assert bm.percolation_verdict([0.0, 0.0, 0.0], [0.4, 0.0, 0.0]) == 0.0   # the crops rarely connect
    assert bm.percolation_text([1.0, 0.0, 0.5]) == "1 0 .50"


def test_the_judge_reports_percolation_against_the_crops(bm):
    ind = tubes()
    crops = [bm.statistics(ind, tau=False) for _ in range(3)]
    shuffled = np.random.default_rng(0).permutation(ind.ravel()).reshape(ind.shape)
    judge = bm.Judge(crops, bm.statistics(shuffled, tau=False))
    assert judge.spread["perc"] == (1.0, 0.0, 0.0)
    broken = ind.copy()
    broken[8] = False                              # cut every tube
    cell = judge.judge(bm.statistics(broken, tau=False))["perc"]
    assert cell == {"value": "0 0 0", "outside": 1.0}
    assert bm.cell(cell) == "0 0 0 (+100%)"
    assert judge.judge(crops[0])["perc"]["outside"] == 0.0
