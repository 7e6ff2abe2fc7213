"""NP_K's voxel constraints (Kopf et al. 2007, section 6.2, eq. 6): the targets and weights
validated (:func:`constraint_arrays`) and carried to the coarser levels
(:func:`coarsen_constraint`).
"""

from __future__ import annotations

import numpy as np

from .. import _validation as check

__all__ = ["coarsen_constraint", "constraint_arrays"]


def constraint_arrays(constraint, constraint_weight, size, channels):
    """Validated ``(N1, N2, N3, C)`` float32 targets and ``(N1, N2, N3)`` float32 weights."""
    if constraint is None:
        if constraint_weight is not None:
            check.fail("constraint_weight was given without a constraint volume")
        return None, None
    t = np.asarray(constraint)
    if t.dtype == object or not np.issubdtype(t.dtype, np.number) or np.issubdtype(t.dtype, np.complexfloating):
        check.fail(f"constraint must be a real-valued array; got dtype {t.dtype}")
    if t.ndim == 3 and channels == 1:
        t = t[..., None]
    want = (*size, channels)
    if t.shape != want:
        check.fail(f"constraint must have shape {want} (N1, N2, N3, C) like the volume; "
                   f"got {t.shape}")
    t = t.astype(np.float32)
    if not np.isfinite(t).all():
        check.fail(f"constraint contains {int((~np.isfinite(t)).sum())} NaN or Inf values; "
                   "give unconstrained voxels weight 0 instead")
    tau = 1.0 if constraint_weight is None else constraint_weight
    tau = np.asarray(tau, dtype=np.float64) if np.isscalar(tau) or np.ndim(tau) == 0 else np.asarray(tau)
    if tau.ndim == 0:
        tau = np.full(size, float(check.real("constraint_weight", float(tau), low=0.0)))
    if tau.shape != tuple(size):
        check.fail(f"constraint_weight must be a number or an array of shape {tuple(size)} "
                   f"(N1, N2, N3); got {tau.shape}")
    if tau.dtype == object or not np.issubdtype(tau.dtype, np.number):
        check.fail(f"constraint_weight must hold numbers; got dtype {tau.dtype}")
    tau = tau.astype(np.float32)
    if not np.isfinite(tau).all() or (tau < 0).any():
        check.fail("constraint_weight must be finite and >= 0 everywhere")
    return np.ascontiguousarray(t), np.ascontiguousarray(tau)


def coarsen_constraint(t, tau, level):
    """The targets and weights of ``level``: weight-averaged targets and mean weights over
    ``2**level``-sided blocks (unchanged at level 0 or without a constraint)."""
    if t is None or level == 0:
        return t, tau
    f = 2 ** level
    n1, n2, n3 = (n // f for n in tau.shape)
    tw = tau.astype(np.float64).reshape(n1, f, n2, f, n3, f)
    wsum = tw.sum(axis=(1, 3, 5))
    tt = (t.astype(np.float64) * tau[..., None]).reshape(n1, f, n2, f, n3, f, -1).sum(axis=(1, 3, 5))
    tt = np.where(wsum[..., None] > 0, tt / np.maximum(wsum[..., None], 1e-300), 0.0)
    return np.ascontiguousarray(tt, dtype=np.float32), np.ascontiguousarray(wsum / f**3, dtype=np.float32)
