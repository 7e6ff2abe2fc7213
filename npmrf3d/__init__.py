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

from importlib.metadata import PackageNotFoundError, version

from . import _cache_folders, data  # noqa: F401  (_cache_folders first: before matplotlib)
from .analysis import metrics
from .config import DEFAULT_SIZE, PRESETS, SUPPORTS, DecisionRule, SynthesisConfig, SynthesisResult
from .errors import ParameterError
from .methods import METHODS, get_method, synthesize
from .methods.chen_wang import chen_wang_synthesize
from .methods.kopf import kopf_synthesize
from .methods.neural import neural_synthesize
from .methods.npmrf import npmrf_synthesize
from .methods.npmrf_3d import npmrf_volume_synthesize
from .methods.npmrf_coherent import coherent_synthesize
from .methods.npmrf_options import make_config
from .methods.volume_lh import volume_synthesize
from .model.exemplar import load_exemplar
from .model.heuristics import HEURISTICS

try:
    __version__ = version("npmrf3d")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

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
