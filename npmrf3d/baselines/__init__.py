"""Baselines the NP-MRF sampler is compared with.

kopf_synthesize
    NP_K: texture optimisation with histogram matching (Kopf et al. 2007; SPEC.md section 6).
"""

from .kopf import KopfConfig, kopf_synthesize

__all__ = ["KopfConfig", "kopf_synthesize"]
