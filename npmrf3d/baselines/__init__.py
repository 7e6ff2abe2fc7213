"""Baselines the NP-MRF sampler is compared with.

kopf_synthesize
    NP_K: texture optimisation with histogram matching (Kopf et al. 2007; SPEC.md section 6).
chen_wang_synthesize
    k-coherence search, discrete solver, position and index histograms (Chen & Wang 2010).
"""

from .chen_wang import ChenWangConfig, chen_wang_synthesize
from .kopf import KopfConfig, kopf_synthesize

__all__ = ["ChenWangConfig", "KopfConfig", "chen_wang_synthesize", "kopf_synthesize"]
