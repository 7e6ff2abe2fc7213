"""The phase control of the 2D methods' histogram prior (``phase_weight``): Otsu's split of a
binned histogram against scikit-image's, the phases of the bins, the volume's phase error, the
target through which the prior charges a phase's cost, and the control at work."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.filters import threshold_otsu

from npmrf3d.errors import ParameterError
from npmrf3d.methods.chen_wang import chen_wang_synthesize
from npmrf3d.methods.npmrf_coherent import coherent_synthesize
from npmrf3d.model.otsu import otsu_split
from npmrf3d.model.phases import PhaseControl, bin_phase_error, bin_phases, phase_prior_target


@pytest.mark.parametrize("seed", range(6))
def test_otsu_split_is_scikit_images_on_a_histogram(seed):
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 50, size=int(rng.integers(3, 40))).astype(np.float64)
    counts[rng.integers(0, counts.size)] += 200
    centres = np.arange(counts.size, dtype=np.float64)
    # scikit-image returns the centre of the last bin of the lower class
    assert otsu_split(counts) == int(threshold_otsu(hist=(counts, centres)))


def test_otsu_split_needs_two_bins():
    with pytest.raises(ParameterError, match="two bins"):
        otsu_split([3.0])


def test_the_bins_above_each_channels_split_are_its_second_phase():
    target = np.array([[9.0, 8.0, 0.0, 0.0, 2.0, 1.0], [0.0, 0.0, 6.0, 0.0, 0.0, 0.0]])
    phases = bin_phases(target)
    np.testing.assert_array_equal(phases[0][[0, 1, 4, 5]], [0, 0, 1, 1])  # the empty bins go either way
    np.testing.assert_array_equal(phases[1], 0)  # one filled bin: nothing to split


def test_the_phase_error_is_each_phases_relative_excess():
    target = np.array([[6.0, 2.0, 1.0, 1.0]])  # the bright phase: 20 % of the exemplar
    phases = np.array([[0, 0, 1, 1]])
    hist = np.array([[7.0, 2.0, 1.0, 0.0]])   # ... and 10 % of the volume
    np.testing.assert_allclose(bin_phase_error(hist, target, phases), [[0.9 / 0.8 - 1.0, 0.1 / 0.2 - 1.0]])


def test_the_prior_through_the_new_target_is_the_plain_prior_minus_the_phase_cost(rng=np.random.default_rng(2)):
    target = rng.random((2, 8)) + 0.1
    hist = rng.random((2, 8)) + 0.1
    phases = rng.integers(0, 2, size=(2, 8))
    costs = rng.random((2, 2))
    kappa = 3.0
    moved = phase_prior_target(target, phases, costs, kappa)
    expected = kappa * np.log(target / hist) - costs[np.arange(2)[:, None], phases]
    np.testing.assert_allclose(kappa * np.log(moved / hist), expected)
    np.testing.assert_array_equal(phase_prior_target(target, phases, costs, 0.0), target)


def test_a_phase_costs_its_excess_and_its_price_times_the_gain():
    control = PhaseControl(np.array([0.0, 0.3]), np.array([-0.5, 0.2]), 0.5)
    np.testing.assert_allclose(control.phase_costs(4.0), 4.0 * 0.5 * np.array([0.0, 0.2 + 0.3]))


def _thin_bright_lines(n=32):
    """A dark image with thin bright lines (1 pixel wide, ~14 % of the pixels)."""
    ex = np.full((n, n), 0.2, dtype=np.float32)
    ex[::7, :] = 0.9
    ex[:, 3::7] = 0.9
    return ex


def test_the_phase_control_brings_a_thin_bright_phase_closer_to_its_share():
    """The coherent sampler erodes thin bright lines (29 % of the exemplar, 24 % of the
    volume); the control restores most of the loss."""
    ex = _thin_bright_lines()
    share = float((ex > 0.5).mean())
    kw = dict(size=16, window=(5, 5), levels=2, iterations=(2, 2), rng=0)
    off = coherent_synthesize(ex, **kw)
    on = coherent_synthesize(ex, phase_weight=16.0, **kw)
    err_off = abs(float((off.volume > 0.5).mean()) - share)
    err_on = abs(float((on.volume > 0.5).mean()) - share)
    assert err_on < err_off / 2
    assert "phase_error" in on.stats["levels"]["level_0"] and "phase_error" not in off.stats["levels"]["level_0"]


def test_chen_wang_records_the_controls_state():
    res = chen_wang_synthesize(_thin_bright_lines(), size=16, window=(5, 5), levels=2, iterations=(2, 2), rng=0,
                               phase_weight=4.0)
    level = res.stats["levels"]["level_0"]
    assert len(level["phase_error"]) == 1 and len(level["phase_error"][0]) == 2 and 0 < level["phase_gain"][0] <= 1


def test_the_default_sampler_passes_its_phase_weight_to_the_coherent_run():
    """``synth --phase-weight`` reaches the coherent sampler's control: the default's run with
    it equals the coherent sampler given the default's options and the same weight."""
    import npmrf3d
    from npmrf3d.methods import npmrf
    from npmrf3d.options import recorded

    ex = _thin_bright_lines()
    config = npmrf.make_config(size=16, window=5, levels=2, phase_weight=16.0)
    options = npmrf._coherent_options(config, False, 2)
    assert options.phase_weight == 16.0 == npmrf.make_config(size=16).phase_weight
    assert npmrf.make_config(size=16, blockwise=True).phase_weight == 16.0
    assert npmrf.make_config(size=16, support="full").phase_weight == 0.0
    on = npmrf3d.synthesize(ex, size=16, window=5, levels=2, phase_weight=16.0, segmented="no", rng=1)
    # the options the run reads (the translation also carries the annealing ones, unread at t0 = 0)
    fields = {k: v for k, v in recorded(options).items() if k not in ("size", "seed")}
    twin = coherent_synthesize(ex, size=16, rng=1, **fields)
    assert np.array_equal(on.volume, twin.volume)
    off = npmrf3d.synthesize(ex, size=16, window=5, levels=2, segmented="no", phase_weight=0.0, rng=1)
    assert "phase_error" in on.stats["levels"]["level_0"] and "phase_error" not in off.stats["levels"]["level_0"]
