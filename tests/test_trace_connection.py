"""The level-by-level connection statistics of benchmarks/trace_connection.py."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def tc():
    return benchmark_module("trace_connection")


def test_a_spanning_tube_and_a_detached_blob(tc):
    ind = np.zeros((16, 16, 16), dtype=bool)
    ind[:, 2:6, 2:6] = True          # 256 voxels joining the faces normal to axis 0
    ind[9:13, 9:13, 9:13] = True     # 64 voxels touching no face
    c = tc.connection(ind)
    assert c["perc"] == [True, False, False]
    assert c["pieces"] == 2
    assert c["largest"] == pytest.approx(256 / 320) and c["spanning"] == pytest.approx(256 / 320)
    assert c["diff"][0] == pytest.approx(256 / 16 ** 3, rel=1e-6) and c["diff"][1] == c["diff"][2] == 0.0


def test_largest_piece_need_not_span(tc):
    ind = np.zeros((16, 16, 16), dtype=bool)
    ind[2:14, 2:14, 2:14] = True     # a large cube inside
    ind[:, 0, 0] = True              # a thin line across
    c = tc.connection(ind, diffusivity=False)
    assert c["largest"] == pytest.approx(12 ** 3 / (12 ** 3 + 16))
    assert c["spanning"] == pytest.approx(16 / (12 ** 3 + 16))
    assert np.isnan(c["diff"]).all()


def test_levels_repeat_up_and_box_average(tc):
    coarse = np.arange(8, dtype=np.float32).reshape(2, 2, 2)
    full = tc.up(coarse, 8)
    assert full.shape == (8, 8, 8) and full[3, 3, 3] == 0 and full[4, 4, 4] == 7
    np.testing.assert_allclose(tc.box(full, 2), coarse)
