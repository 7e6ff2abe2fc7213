"""What every registered method must do, run through the registry (:data:`npmrf3d.methods.METHODS`).

A new method adds one entry to :data:`CASES` (small, fast options for it) and gets these tests:
the common signature gives the public function's volume, a seed fixes the volume, and a run
interrupted after its first level resumes from its checkpoint to the uninterrupted volume.
"""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.errors import ParameterError
from npmrf3d.methods import METHODS
from npmrf3d.model.exemplar import resolve_exemplars

#: id -> (method name, keyword arguments of its public function): tiny runs of two levels.
CASES = {
    # the checkerboard is segmented: "npmrf-icm" runs the coherent default with --window as
    # given, "npmrf-segmented" with the segmented preset (which sets the window itself)
    "npmrf-icm": ("npmrf", dict(size=16, window=5, levels=2, segmented="no")),
    "npmrf-segmented": ("npmrf", dict(size=16, levels=2)),
    "npmrf-anneal": ("npmrf", dict(size=16, window=5, levels=2, relaxation="anneal", support="full",
                                   proposals=2)),
    "npmrf-coherent-anneal": ("npmrf", dict(size=16, window=5, levels=2, relaxation="anneal", proposals=2,
                                            segmented="no")),
    "npmrf-temperatures": ("npmrf", dict(size=16, window=5, levels=2, temperatures=True, segmented="no")),
    "kopf": ("kopf", dict(size=16, window=4, levels=2, iterations=2)),
    "chen-wang": ("chen-wang", dict(size=16, window=(4, 4), levels=2, iterations=(2, 2))),
    "coherent": ("coherent", dict(size=16, window=(4, 4), levels=2, iterations=(2, 2))),
    "volume-lh": ("volume-lh", dict(size=16, levels=2)),
    "npmrf-3d": ("npmrf-3d", dict(size=16, levels=2, passes=1)),
}
#: What the resume test changes to make a different configuration (default: the window).
DIFFERENT = {"npmrf-segmented": {"segmented": "no"}}
#: Methods that take a 3D exemplar (run on ``tiny_volume`` instead of ``tiny_grey``).
VOLUME_METHODS = ("volume-lh", "npmrf-3d")


@pytest.fixture
def tiny_volume() -> np.ndarray:
    """A 24^3 volume of layers, period 6 along axis 1."""
    profile = (np.arange(24) % 6 < 3).astype(np.float32)
    return np.broadcast_to(profile[None, :, None], (24, 24, 24)).copy()


def _exemplar_for(name, request):
    return request.getfixturevalue("tiny_volume" if name in VOLUME_METHODS else "tiny_grey")


#: Methods whose cases need an optional extra: ``neural`` (torch) runs these same tests in
#: ``tests_neural/test_registry.py``, which ``.ci/run`` runs after installing ``.[neural]``.
EXTRA_METHODS = {"neural"}


def test_every_registered_method_has_a_case():
    assert {name for name, _ in CASES.values()} == set(METHODS) - EXTRA_METHODS


@pytest.mark.parametrize("case", sorted(CASES))
def test_common_signature_equals_the_public_function(case, request):
    name, kwargs = CASES[case]
    method = METHODS[name]
    exemplar = _exemplar_for(name, request)
    public = method.synthesize(exemplar, rng=3, **kwargs)
    config = method.make_config(**kwargs, seed=3)
    if name in VOLUME_METHODS:
        per_view = {"volume": exemplar[..., None]}
    else:
        per_view = resolve_exemplars(exemplar, None, config.views, **method.fit(config))
    common = method.run(per_view, config, np.random.default_rng(3))
    np.testing.assert_array_equal(public.volume, common.volume)
    assert common.config == public.config


@pytest.mark.parametrize("case", sorted(CASES))
def test_resume_from_checkpoint_gives_the_uninterrupted_result(case, tmp_path, request):
    name, kwargs = CASES[case]
    tiny_grey = _exemplar_for(name, request)
    synthesize = METHODS[name].synthesize
    path = tmp_path / "run.npz"
    full = synthesize(tiny_grey, rng=5, **kwargs).volume

    class Stop(Exception):
        pass

    def interrupt(level, step, steps, value):
        if level == 0 and step == 1:
            raise Stop

    with pytest.raises(Stop):
        synthesize(tiny_grey, rng=5, progress=interrupt, checkpoint=path, **kwargs)
    assert path.exists()
    resumed = synthesize(tiny_grey, rng=5, checkpoint=path, **kwargs)
    np.testing.assert_array_equal(full, resumed.volume)
    with pytest.raises(ParameterError, match="different configuration"):
        synthesize(tiny_grey, rng=5, checkpoint=path, **{**kwargs, **DIFFERENT.get(case, {"window": 3})})
