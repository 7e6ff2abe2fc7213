"""Many ``exp`` at once, in loops the compiler vectorises.

The Parzen label stage takes ``exp`` of about a thousand log weights per site and view
(:func:`npmrf3d._kernels.parzen.label_weights`): called one by one from libm, those calls cost
more than the neighbour distances themselves. :func:`relative_weights` computes them with plain
float32 multiplies and adds, so that LLVM turns its loops into SIMD code (8 or 16 lanes):

* ``x = k ln 2 + r`` with ``k`` the nearest integer to ``x / ln 2`` (found by adding and
  subtracting ``1.5 * 2**23``, which rounds to an integer without a float-to-int conversion)
  and ``|r| <= ln 2 / 2``, ``ln 2`` split in two parts (Cody and Waite) so that ``r`` is exact;
* ``exp(r)`` by its Taylor polynomial of degree 7 in Horner form (truncation below 5e-9
  relative);
* ``2**k`` written straight into the exponent bits, through an int32 view of a float32 buffer.

Why float32: the weights are ``exp(-(D_p - D_min) / 2h^2)`` of float32 distances ``D_p``, whose
own rounding already moves a log weight of -40 by about 2e-6; the float32 ``exp`` adds at most
a few float32 units in the last place (about 3e-7 relative, tests/test_vecmath.py), so the
model keeps its precision while the loop runs on twice the lanes of float64.

Nothing here depends on the CPU: with ``fastmath`` off the compiled code does each IEEE
operation in the written order at any vector width, so the weights are the same on every
machine (libm's ``exp`` may differ between platforms in the last bit; this one does not).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import jit, jit_inline

__all__ = ["WEIGHT_LOG_MIN", "relative_weight", "relative_weights"]

#: Log weights below this are not computed by :func:`relative_weights` (they are set to 0): the
#: float32 result would leave the normal range. Callers that keep such weights take them from
#: ``math.exp`` one by one (they only occur with pruning off, ``prune > 87``).
WEIGHT_LOG_MIN = -87.0

_LOG2E = np.float32(1.4426950408889634)
_LN2_HI = np.float32(0.693145751953125)  # ln 2 to 16 significant bits: k * _LN2_HI is exact
_LN2_LO = np.float32(1.428606765330187e-06)  # ln 2 - _LN2_HI
_ROUND = np.float32(12582912.0)  # 1.5 * 2**23: x + _ROUND rounds x to an integer in the low bits
_ROUND_BITS = np.int32(0x4B400000)  # the bits of _ROUND
_C = (np.float32(1.0 / 5040.0), np.float32(1.0 / 720.0), np.float32(1.0 / 120.0),
      np.float32(1.0 / 24.0), np.float32(1.0 / 6.0), np.float32(0.5), np.float32(1.0))


@jit_inline
def _reduced_exp(v):
    """``exp(v)`` of a float32 ``v >= WEIGHT_LOG_MIN`` in two parts, ``(q, t)``: ``t - _ROUND``
    is the integer ``k`` (``t`` keeps it in its low bits) and ``q = exp(v - k ln 2)`` from the
    degree-7 polynomial, so that ``exp(v) = q * 2**k``."""
    c7, c6, c5, c4, c3, c2, c1 = _C
    t = v * _LOG2E + _ROUND
    kf = t - _ROUND
    r = (v - kf * _LN2_HI) - kf * _LN2_LO
    q = c7 * r + c6
    q = q * r + c5
    q = q * r + c4
    q = q * r + c3
    q = q * r + c2
    q = q * r + c1
    q = q * r + c1
    return q, t


@jit
def relative_weights(dist, n, d_min, inv, lowest, out, scratch):
    """``out[p] = exp(-(dist[p] - d_min) * inv)`` (float32) for ``p < n``.

    ``dist`` (>= n,) float32 with ``dist[p] >= d_min``; ``d_min`` (a float32 value) and
    ``inv >= 0``; the log weight is formed in float32 (relative error 6e-8, i.e. 2.4e-6 absolute
    at -40, the size of the distances' own rounding there). Where it is below ``lowest``
    (``>= WEIGHT_LOG_MIN``: a pruning threshold) the weight is 0. ``out`` and ``scratch``
    (>= n,) float32.
    """
    top = np.float32(d_min)
    scale32 = np.float32(inv)
    floor = np.float32(max(lowest, WEIGHT_LOG_MIN))
    for p in range(n):
        lw = (top - dist[p]) * scale32
        low = lw < floor
        q, t = _reduced_exp(floor if low else lw)
        out[p] = np.float32(0.0) if low else q
        scratch[p] = t
    bits = scratch[:n].view(np.int32)
    for p in range(n):  # 2**k: (k + 127) in the exponent field
        bits[p] = (bits[p] - _ROUND_BITS + np.int32(127)) << np.int32(23)
    scale = bits.view(np.float32)
    for p in range(n):
        out[p] = out[p] * scale[p]


@jit_inline
def relative_weight(d, top, scale32, floor):
    """One weight of :func:`relative_weights`, by the same float32 operations in the same order
    (so the same bits): ``exp((top - d) * scale32)`` of a float32 distance ``d``, where ``top``,
    ``scale32`` and ``floor`` are the float32 numbers that function forms from ``d_min``,
    ``inv`` and ``max(lowest, WEIGHT_LOG_MIN)``; 0 where the log weight is below ``floor``.

    ``2**k`` comes from ``math.ldexp(1.0, k)`` here, where that function spells it in the
    exponent bits: ``t - _ROUND`` is the integer ``k`` exactly, and ``k >= -126`` above the
    floor, so ``2**k`` is a normal float32 either way.
    """
    lw = (top - d) * scale32
    if lw < floor:
        return np.float32(0.0)
    q, t = _reduced_exp(lw)
    return q * np.float32(math.ldexp(1.0, int(t - _ROUND)))
