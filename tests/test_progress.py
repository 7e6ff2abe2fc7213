"""Progress bars count the work that will really be done: ICM's expected sweeps
(npmrf3d.model.relax.icm.expected_sweeps), from the cooling step, corrected after every sweep."""

from __future__ import annotations

import pytest

import npmrf3d
from npmrf3d.cli._progress import LevelProgress
from npmrf3d.model.relax.icm import expected_sweeps


def test_expected_sweeps_bounds():
    kw = dict(n_voxels=1000, xi=-3.0, stop=0.95, max_sweeps=30, n_union=60)
    assert expected_sweeps([1000.0], **kw) == 12
    assert expected_sweeps([1000.0], **{**kw, "max_sweeps": 5}) == 5
    assert expected_sweeps([1000.0, 990.0], **kw) == 30  # barely cooling: the hard limit
    assert expected_sweeps([1000.0, 500.0, 40.0], **kw) == 2  # stopped
    assert expected_sweeps([1000.0, 900.0, 800.0], **kw) >= 3
    assert expected_sweeps([0.0], **kw) == 1


@pytest.mark.parametrize("size, window, levels", [(16, 5, 2), (12, 3, 1)])
def test_icm_progress_counts_the_sweeps_the_stop_rule_needs(size, window, levels):
    calls = []
    result = npmrf3d.synthesize(None, size=size, window=window, levels=levels, rng=0, variant="sharp",
                                progress=lambda *a: calls.append(a))
    for index, level in enumerate(range(levels - 1, -1, -1)):
        done = result.stats["levels"][f"level_{level}"]["sweeps"]
        reported = [c for c in calls if c[0] == level]
        first_guess, last = reported[0][2], reported[-1]
        assert last[1] == done and last[2] == done  # the bar ends exactly full
        assert done / 2 <= first_guess <= 2 * done, (level, first_guess, done)
        assert all(c[2] <= result.config.max_sweeps for c in reported)
        assert first_guess < result.config.max_sweeps  # not --max-sweeps


def test_level_bar_total_follows_the_corrections():
    bar = LevelProgress((8, 8, 8), enabled=True)
    bar(0, 0, 10, 1.0)
    assert bar.bar.total == 10
    bar(0, 1, 6, 0.5)
    assert bar.bar.total == 6 and bar.bar.n == 1
    bar.close()
