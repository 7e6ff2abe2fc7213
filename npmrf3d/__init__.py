"""npmrf3d: 3D solid textures from one 2D exemplar (or a 3D one).

Public API
----------
synthesize
    Every method behind one function: ``synthesize(exemplar=None, *, method="npmrf", size=64,
    rng=None, progress=None, checkpoint=None, **options)``.
npmrf_synthesize, coherent_synthesize, kopf_synthesize, chen_wang_synthesize,
volume_synthesize, npmrf_volume_synthesize, neural_synthesize
    Each method's own function, with the same leading signature and its options documented.
METHODS, get_method
    The method registry: every way of making a volume by name, each with its frozen
    configuration class, its ``run(per_view_exemplars, config, rng, *, progress, checkpoint)``
    and its memory estimate.
data, metrics
    Bundled exemplars (``data.path(name)``) and the comparison metrics (``metrics.evaluate``).
load_exemplar
    Read an exemplar image or array as float32 (H, W, C).
SynthesisConfig, SynthesisResult, DecisionRule, SUPPORTS, PRESETS, DEFAULT_SIZE
    The NP-MRF sampler's configuration, its estimator supports and decision-rule presets, the result object every method
    returns, and the output size when none is given (every method).
ParameterError
    The exception raised for user mistakes.
"""

import importlib

from . import _cache_folders  # noqa: F401  (first: settles matplotlib's folder before it is imported)

#: Where each public name lives: ``import npmrf3d`` imports none of them (numba, scipy and
#: matplotlib take a second or more); the first use of a name imports its module (PEP 562).
_LAZY = {
    "DEFAULT_SIZE": ".config", "PRESETS": ".config", "SUPPORTS": ".config", "DecisionRule": ".config",
    "SynthesisConfig": ".config", "SynthesisResult": ".config",
    "ParameterError": ".errors",
    "METHODS": ".methods", "get_method": ".methods", "synthesize": ".methods",
    "chen_wang_synthesize": ".methods.chen_wang",
    "kopf_synthesize": ".methods.kopf",
    "neural_synthesize": ".methods.neural",
    "npmrf_synthesize": ".methods.npmrf",
    "npmrf_volume_synthesize": ".methods.npmrf_3d",
    "coherent_synthesize": ".methods.npmrf_coherent",
    "make_config": ".methods.npmrf_options",
    "volume_synthesize": ".methods.volume_lh",
    "load_exemplar": ".model.exemplar",
    "HEURISTICS": ".model.heuristics",
}
#: Public names that are modules.
_LAZY_MODULES = {"data": ".data", "metrics": ".analysis.metrics"}


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("npmrf3d")
    except PackageNotFoundError:  # running from a source tree that was not installed
        return "0.0.0+unknown"


def __getattr__(name: str):
    """Import a public name's module on its first use and keep the name (PEP 562)."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _LAZY_MODULES:
        value = importlib.import_module(_LAZY_MODULES[name], __name__)
    elif name == "__version__":
        value = _version()
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "DEFAULT_SIZE",
    "HEURISTICS",
    "METHODS",
    "PRESETS",
    "SUPPORTS",
    "DecisionRule",
    "ParameterError",
    "SynthesisConfig",
    "SynthesisResult",
    "__version__",
    "chen_wang_synthesize",
    "coherent_synthesize",
    "data",
    "get_method",
    "kopf_synthesize",
    "load_exemplar",
    "make_config",
    "metrics",
    "neural_synthesize",
    "npmrf_synthesize",
    "npmrf_volume_synthesize",
    "synthesize",
    "volume_synthesize",
]
