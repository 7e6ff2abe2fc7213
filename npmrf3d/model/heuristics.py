"""The four heuristics that turn three 2D LCPDFs into one voxel value (docs/model.md, section 3).

========  ===================================================  ==========
name      rule                                                 annealing
========  ===================================================  ==========
ML_H1a    per view ``argmax L_v``; keep the least probable one  no
ML_H1b    per view ``argmax L_v``; average the values           no
ML_H2a    ``argmax_lam min_v L_v(lam)``                         yes
ML_H2b    ``argmax_lam prod_v L_v(lam)`` (sum of logs)          yes
========  ===================================================  ==========

With one constrained view all four reduce to the plain 2D NP-MRF. The compiled rule is
:func:`npmrf3d._kernels.relax.choose_label`; this module is the registry of names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _validation as check
from .._kernels import relax as _relax

__all__ = ["HEURISTICS", "Heuristic", "choose", "get_heuristic"]


@dataclass(frozen=True)
class Heuristic:
    """A named heuristic: its kernel code and whether it defines an objective for annealing."""

    name: str
    code: int
    objective: bool
    description: str


HEURISTICS: dict[str, Heuristic] = {
    h.name: h
    for h in (
        Heuristic("ML_H1a", _relax.H1A, False, "per-view argmax, keep the least probable"),
        Heuristic("ML_H1b", _relax.H1B, False, "per-view argmax, average the values"),
        Heuristic("ML_H2a", _relax.H2A, True, "argmax of the minimum over views"),
        Heuristic("ML_H2b", _relax.H2B, True, "argmax of the product over views"),
    )
}

DECISIONS = {"argmax": _relax.ARGMAX, "sample": _relax.SAMPLE}


def get_heuristic(name: str) -> Heuristic:
    """Look a heuristic up by name (case-insensitive); the error lists the valid names."""
    return HEURISTICS[check.choice("heuristic", name, HEURISTICS)]


def choose(log_l: np.ndarray, labels: np.ndarray, heuristic: str = "ML_H2b", *,
           decision: str = "argmax", tau: float = 1.0, u: float = 0.5,
           penalty: np.ndarray | None = None) -> tuple[int, np.ndarray]:
    """Apply a heuristic to per-view log-LCPDFs.

    Parameters
    ----------
    log_l : (V, K) ndarray of per-view log-LCPDFs
    labels : (K, C) float32 ndarray
    heuristic : str
    decision : {"argmax", "sample"}
    tau : float
        Temperature of ``sample``.
    u : float in [0, 1)
        The uniform number a ``sample`` decision consumes.
    penalty : (K,) ndarray, optional
        Added to the ML_H2a/ML_H2b score.

    Returns
    -------
    label : int (-1 for ML_H1b)
    value : (C,) float32 ndarray
    """
    h = get_heuristic(heuristic)
    code = DECISIONS[check.choice("decision", decision, DECISIONS)]
    n_labels = labels.shape[0]
    penalty = np.zeros(n_labels) if penalty is None else np.asarray(penalty, dtype=np.float64)
    value = np.empty(labels.shape[1], dtype=np.float32)
    label = _relax.choose_label(np.ascontiguousarray(log_l, dtype=np.float64), h.code, code,
                                float(tau), float(u), penalty,
                                np.ascontiguousarray(labels, dtype=np.float32), value,
                                np.empty(n_labels))
    return int(label), value
