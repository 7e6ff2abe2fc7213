"""The method registry: every way of making a volume, by name.

Each entry of :data:`METHODS` is a :class:`npmrf3d.config.SynthesisMethod`: the method's
``run(per_view_exemplars, config, rng, *, progress=None, checkpoint=None)``, its validating
``make_config``, its frozen configuration class (whose field defaults are the defaults of the
API and the command line), its public one-call function and what its exemplars must fit. The
studies (:mod:`npmrf3d.studies.grid`, :mod:`npmrf3d.studies.runner`), the ``synth`` and
``baseline`` commands, the run record and the report all read it.

Adding a method is one new module plus one line here: the module defines ``METHOD =
SynthesisMethod(name=..., run=..., ...)`` (see :data:`npmrf3d.methods.npmrf.METHOD`) and the line
adds it to :data:`METHODS`. The studies' structureless control and ground-truth crop are not
methods (they make no volume from an exemplar); they stay in :mod:`npmrf3d.studies.runner`.
"""

from __future__ import annotations

from .. import _validation as check
from .. import resources
from ..config import DEFAULT_SIZE, SynthesisMethod
from . import chen_wang, kopf, npmrf, npmrf_3d, npmrf_coherent, volume_lh
from .neural import METHOD as NEURAL

__all__ = ["ALIASES", "METHODS", "check_resources", "estimate", "get_method", "synthesize"]

#: name -> method, in the order ``npmrf3d info`` lists them.
METHODS: dict[str, SynthesisMethod] = {
    m.name: m for m in (
        npmrf.METHOD,
        npmrf_coherent.METHOD,
        kopf.METHOD,
        chen_wang.METHOD,
        volume_lh.METHOD,
        npmrf_3d.METHOD,
        NEURAL,
    )
}

#: Other spellings accepted for a registered name.
ALIASES: dict[str, str] = {"np-mrf": "npmrf", "np_k": "kopf", "npk": "kopf", "chen_wang": "chen-wang",
                           "cw": "chen-wang", "npmrf-coherent": "coherent"}


def get_method(name: str) -> SynthesisMethod:
    """The registered method ``name`` (or an alias of it).

    >>> get_method("kopf").config_class.__name__
    'KopfConfig'
    """
    key = ALIASES.get(name, name) if isinstance(name, str) else name
    if key not in METHODS:
        check.fail(f"method must be one of {', '.join(METHODS)}; got {name!r}")
    return METHODS[key]


def estimate(method: SynthesisMethod, config, per_view: dict) -> resources.Estimate:
    """What a run of ``method`` with ``config`` will need (``per_view``: view -> exemplar array
    or its (H, W, C) shape), from the method's ``resources`` hook (a generic one without)."""
    hook = method.resources or resources.generic_estimate
    return hook(config, per_view)


def check_resources(method: SynthesisMethod, config, per_view: dict, **kwargs) -> resources.Estimate:
    """:func:`estimate`, refused by :func:`npmrf3d.resources.check_memory` beyond the machine's
    available memory (a ``ResourceError``, one line with exit 2 on the command line)."""
    needed = estimate(method, config, per_view)
    resources.check_memory(needed, **kwargs)
    return needed


def synthesize(exemplar=None, *, method: str = "npmrf", size=DEFAULT_SIZE, rng=None, progress=None,
               checkpoint=None, **options):
    """Make a solid texture with any registered method: one function for all of them.

    Parameters
    ----------
    exemplar : path, array or None
        The exemplar: a 2D image (grey, colour or any channel count) for the 2D methods, a
        volume for ``volume-lh`` and ``npmrf-3d``. None: the bundled default image (2D methods).
    method : str
        A name of :data:`METHODS` (``npmrf3d info`` lists them): ``npmrf`` (default),
        ``coherent``, ``kopf``, ``chen-wang``, ``volume-lh``, ``npmrf-3d``, ``neural``.
    size : int or (N1, N2, N3)
        Output size in voxels.
    rng : None, int or numpy Generator
        The only source of randomness: the result depends on it, never on the thread count.
    progress : callable, optional
        ``progress(level, step, steps, value)`` before the first step of each level and after
        every step.
    checkpoint : path, optional
        A file written as the run goes; a matching one is resumed from.
    **options
        The method's options: the fields of its configuration class
        (``METHODS[method].config_class``), documented with the method's own function
        (:func:`npmrf3d.methods.npmrf.npmrf_synthesize`, :func:`npmrf3d.methods.kopf.kopf_synthesize`,
        ...). ``exemplars`` (view -> exemplar) gives some views of a 2D method their own exemplar.
        An option the method does not have is refused with one clear error.

    Returns
    -------
    SynthesisResult
        ``volume`` (N1, N2, N3, C) float32, ``history``, ``config``, ``timings``, ``labels``,
        ``stats``.

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> synthesize(stripes, method="kopf", size=8, window=4, levels=1, iterations=1, rng=0).volume.shape
    (8, 8, 8, 1)
    """
    return get_method(method).synthesize(exemplar, size=size, rng=rng, progress=progress,
                                         checkpoint=checkpoint, **options)
