"""The ``neural`` method through the registry: the tests every method passes
(``tests/test_methods.py``), here because they need torch."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.errors import ParameterError
from npmrf3d.methods import METHODS, check_resources
from npmrf3d.model.exemplar import resolve_exemplars
from tests_neural.conftest import TINY


def test_common_signature_equals_the_public_function(exemplar):
    method = METHODS["neural"]
    public = method.synthesize(exemplar, rng=3, **TINY)
    config = method.make_config(**TINY, seed=3)  # an integer rng is also the model's seed
    per_view = resolve_exemplars(exemplar, None, config.views, **method.fit(config))
    common = method.run(per_view, config, np.random.default_rng(3))
    np.testing.assert_array_equal(public.volume, common.volume)
    assert common.config == public.config
    assert public.volume.shape == (16, 16, 16, 1)
    assert set(public.timings) == {"train", "generate", "total"}
    assert len(public.history[0]) == TINY["iterations"]
    assert check_resources(method, config, per_view).bytes > public.volume.nbytes


def test_resume_from_checkpoint_gives_the_uninterrupted_result(tmp_path, exemplar):
    synthesize = METHODS["neural"].synthesize
    kwargs = {**TINY, "checkpoint_every": 1}
    path = tmp_path / "run.ckpt"
    full = synthesize(exemplar, rng=5, **kwargs).volume

    class Stop(Exception):
        pass

    def interrupt(level, step, steps, value):
        if level == 0 and step == 1:
            raise Stop

    with pytest.raises(Stop):
        synthesize(exemplar, rng=5, progress=interrupt, checkpoint=path, **kwargs)
    assert path.exists()
    resumed = synthesize(exemplar, rng=5, checkpoint=path, **kwargs)
    np.testing.assert_array_equal(full, resumed.volume)
    with pytest.raises(ParameterError, match="different configuration"):
        synthesize(exemplar, rng=5, checkpoint=path, **{**kwargs, "filters": 3})


def test_a_study_can_name_it():
    from npmrf3d.studies.grid import ALGORITHMS

    assert "neural" in ALGORITHMS
