"""The default method's options are written once: a field of :class:`SynthesisConfig` is a
keyword of ``make_config``, is checked by its own limits and reaches the coherent sampler by its
name; the segmented preset is data over the coherent sampler's options; a run builds the coherent
configuration and counts the exemplar's grey values once."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from npmrf3d.config import SynthesisConfig
from npmrf3d.errors import ParameterError
from npmrf3d.methods import chen_wang, npmrf, npmrf_coherent
from npmrf3d.methods.npmrf_coherent import SEGMENTED, CoherentConfig, make_coherent_config
from npmrf3d.methods.npmrf_options import make_config
from npmrf3d.options import flat_options, options_of, shared


def test_make_config_takes_every_option_of_the_configuration_and_refuses_others():
    params = inspect.signature(make_config).parameters
    assert list(params) == [*flat_options(SynthesisConfig), "variant"]
    assert "rule" not in params and "centre_bandwidth" in params  # the rule's options in its place
    assert params["upsample"].default is None and params["window"].default == SynthesisConfig.window
    with pytest.raises(ParameterError, match=r"^there is no option 'windw'; the options are size, window, "):
        make_config(windw=5)
    assert list(inspect.signature(make_coherent_config).parameters) == list(options_of(CoherentConfig))


@pytest.mark.parametrize("name, value, words", [
    ("max_sweeps", 0, "max_sweeps must be"), ("proposal", "nope", "proposal must be one of"),
    ("toroidal_exemplar", "yes", "toroidal_exemplar must be True or False"),
    ("whole_voxels", 0, "whole_voxels must be"), ("grid", 9, "grid must be between 1 and 7"),
])
def test_each_option_is_checked_by_its_field(name, value, words):
    with pytest.raises(ParameterError, match=words):
        make_config(size=16, levels=2, **{name: value})


def test_every_option_the_two_configurations_share_reaches_the_coherent_sampler():
    config = make_config(size=32, levels=2, temperatures=True, xi=-2.0, stop=0.5, max_sweeps=4,
                         upsample="1/8", inherit="fixed", centre_bandwidth=0.3, outlier=0.05,
                         phase_weight=3.0, heuristic="ML_H2a", views="front,top", seed=5)
    (run,) = npmrf._coherent_runs(config, False)
    carried = shared(config, CoherentConfig)
    assert {"xi", "stop", "max_sweeps", "upsample", "inherit", "centre_bandwidth", "outlier",
            "phase_weight", "heuristic", "views", "seed", "size"} <= set(carried)
    for name, value in carried.items():
        if name not in ("window", "levels", "t0"):  # per level; t0 0 unless annealing
            assert getattr(run, name) == value, name
    assert run.window == (config.window,) * 2 and run.icm and run.t0 == 0.0
    annealed = npmrf._coherent_runs(make_config(size=32, levels=2, relaxation="anneal", proposals=3), False)[0]
    assert annealed.iterations == (3, 3) and annealed.t0 == SynthesisConfig.t0


def test_the_segmented_preset_is_data_over_the_coherent_options():
    assert SEGMENTED.changes() == {"window": SEGMENTED.window, "value_weight": SEGMENTED.value_weight,
                                   "smoothness": SEGMENTED.smoothness, "attached": SEGMENTED.attached}
    runs = npmrf._coherent_runs(make_config(size=32, levels=3), True)
    assert [r.levels for r in runs] == list(SEGMENTED.pyramids(3))
    for r in runs:
        assert r.window == (SEGMENTED.window,) * r.levels and r.value_weight == SEGMENTED.value_weight
        assert r.smoothness == SEGMENTED.smoothness and r.attached == SEGMENTED.attached
        assert r.grid == 1
    plain = npmrf._coherent_runs(make_config(size=32, levels=3), False)[0]
    assert plain.value_weight == CoherentConfig.value_weight and plain.grid == 2


def test_a_run_validates_its_coherent_configuration_and_counts_grey_values_once(monkeypatch):
    calls = {"chen-wang": 0, "unique": 0}
    make_cw, unique = chen_wang.make_chen_wang_config, np.unique

    def counted_cw(**options):
        calls["chen-wang"] += 1
        return make_cw(**options)

    def counted_unique(*args, **kwargs):
        calls["unique"] += 1
        return unique(*args, **kwargs)

    monkeypatch.setattr(chen_wang, "make_chen_wang_config", counted_cw)
    monkeypatch.setattr(npmrf_coherent, "_COUNTED", {})
    monkeypatch.setattr(np, "unique", counted_unique)
    npmrf._coherent_runs.cache_clear()
    binary = {"front": np.tile(np.array([[0.0], [1.0]], np.float32), (16, 32))[..., None]}
    photo = {"front": np.linspace(0, 1, 32 * 32, dtype=np.float32).reshape(32, 32, 1)}
    config = make_config(size=16, levels=2, views="front", blockwise=True, seed=11)
    for _ in range(3):  # the memory estimate, the block aprons, the run's own decision
        npmrf.npmrf_resources(config, binary)
        npmrf.npmrf_aprons(config, binary)
        assert npmrf.segmented(config, binary) and not npmrf.segmented(config, photo)
    assert calls == {"chen-wang": 1, "unique": 2}  # one pyramid when blockwise; each exemplar once
    levels = npmrf_coherent.coherent_levels(npmrf._coherent_runs(config, True)[0], binary)
    assert calls["chen-wang"] == 1 and levels.config.window == (SEGMENTED.window,) * 2
