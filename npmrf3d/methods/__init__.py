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
from ..config import SynthesisMethod
from . import chen_wang, kopf, npmrf, npmrf_3d, npmrf_coherent, volume_lh
from .neural import METHOD as NEURAL

__all__ = ["ALIASES", "METHODS", "check_resources", "estimate", "get_method"]

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
                           "cw": "chen-wang", "npmrf-coherent": "coherent",
                           "seed002": "volume-lh"}


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
