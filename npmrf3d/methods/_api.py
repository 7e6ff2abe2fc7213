"""The one shape of every method's public function.

Every method's own function has the same leading signature::

    xxx_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress=None, checkpoint=None,
                   exemplars=None, **options)

where ``options`` are the fields of the method's frozen configuration class, validated by the
method's ``make_config`` (the single source of the option names and defaults).
:func:`prepare` does what they share: it refuses an option the method does not have (one line
naming it and listing the method's options), validates the configuration with the seed taken
from ``rng``, loads and checks the exemplars, and refuses a run the machine cannot hold.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .. import _validation as check
from .._kernels._jit import check_thread_setting
from ..config import SynthesisMethod
from ..model.exemplar import resolve_exemplars
from ..resources import check_memory, generic_estimate

__all__ = ["option_names", "prepare", "seed_of", "settled"]


def seed_of(rng) -> int | None:
    """The integer seed that ``rng`` is (recorded in the configuration), or None for a Generator."""
    return rng if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) else None


def option_names(method: SynthesisMethod) -> tuple[str, ...]:
    """The keyword options of ``method`` (its ``make_config`` parameters but ``size`` and ``seed``)."""
    params = inspect.signature(method.make_config).parameters
    return tuple(name for name in params if name not in ("size", "seed"))


def settled(method: SynthesisMethod, config, per_view: Mapping[str, np.ndarray]):
    """``config`` with what it leaves to the exemplars decided (the method's ``settle``)."""
    return config if method.settle is None else method.settle(config, per_view)


def prepare(method: SynthesisMethod, exemplar, exemplars: Mapping | None, *, size, rng,
            options: Mapping[str, Any],
            load: Callable[..., dict] | None = None,
            memory: bool = True, progress=None,
            checkpoint=None) -> tuple[Any, np.random.Generator, dict]:
    """``(config, generator, per_view)`` of a call of ``method``'s public function (the
    configuration settled on the exemplars, :func:`settled`).

    ``load(exemplar, exemplars, config)`` reads the exemplars (default: one 2D exemplar per
    constrained view, checked against the method's ``fit``). ``memory=False`` leaves out the
    memory check (a run that will go to another machine). ``progress`` and ``checkpoint``, the
    public function's own, are checked before anything else (a callable or None; a path or
    None), so that a wrong one is refused up front rather than failing in the run.
    """
    check.progress(progress)
    check.checkpoint(checkpoint)
    check_thread_setting()  # a NUMBA_NUM_THREADS of 0 is refused, not silently replaced
    known = option_names(method)
    unknown = sorted(set(options) - set(known))
    if unknown:
        check.fail(f"method {method.name} has no option {unknown[0]!r}; its options are "
                   f"{', '.join(known)}")
    config = method.make_config(size=size, seed=seed_of(rng), **options)
    generator = check.rng(rng)
    if load is None:
        fit = method.fit(config)
        per_view = resolve_exemplars(exemplar, exemplars, config.views, window=fit["window"],
                                     levels=fit["levels"], toroidal=fit.get("toroidal", False))
    else:
        per_view = load(exemplar, exemplars, config)
    config = settled(method, config, per_view)
    if memory:
        check_memory((method.resources or generic_estimate)(config, per_view))
    return config, generator, per_view
