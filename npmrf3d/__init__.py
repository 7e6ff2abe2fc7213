"""npmrf3d: 3D solid textures from one 2D exemplar with a non-parametric Markov random field.

Public API
----------
synthesize
    Multi-scale NP-MRF synthesis (ICM with per-voxel temperatures or simulated annealing,
    four heuristics, grey, colour or any channel count).
kopf_synthesize
    The NP_K baseline (Kopf et al. 2007), same result object.
data, metrics
    Bundled exemplars (``data.path(name)``) and the comparison metrics (``metrics.evaluate``).
load_exemplar
    Read an exemplar image or array as float32 (H, W, C).
SynthesisConfig, SynthesisResult, DecisionRule, VARIANTS
    Run configuration, result object and decision-rule presets.
METHODS, get_method
    The method registry: every way of making a volume by name (``npmrf``, ``kopf``), each with
    ``run(per_view_exemplars, config, rng, *, progress, checkpoint)`` and its config class.
ParameterError
    The exception raised for user mistakes.
"""

from importlib.metadata import PackageNotFoundError, version

from . import data
from .analysis import metrics
from .config import VARIANTS, DecisionRule, SynthesisConfig, SynthesisResult
from .errors import ParameterError
from .methods import METHODS, get_method
from .methods.kopf import kopf_synthesize
from .methods.npmrf import make_config, synthesize
from .model.exemplar import load_exemplar
from .model.heuristics import HEURISTICS

try:
    __version__ = version("npmrf3d")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

__all__ = [
    "HEURISTICS",
    "METHODS",
    "VARIANTS",
    "DecisionRule",
    "ParameterError",
    "SynthesisConfig",
    "SynthesisResult",
    "__version__",
    "data",
    "get_method",
    "kopf_synthesize",
    "load_exemplar",
    "metrics",
    "make_config",
    "synthesize",
]
