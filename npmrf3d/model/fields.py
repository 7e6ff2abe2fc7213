"""Vector and frame fields that deform a volume synthesised from a 3D exemplar (the
vector-field deformation method, IET Image Processing 2012).

A *frame* ``R`` at a voxel is a rotation matrix whose columns are where the exemplar's axes
0, 1, 2 point in the output: an exemplar offset ``D`` appears as the output offset ``R D``. A
field is one frame per output voxel, ``(N1, N2, N3, 3, 3)`` float32. It is given as

* a name (:data:`FIELDS`), with ``angle`` in degrees:

  - ``none``: the identity everywhere (no deformation);
  - ``twist``: rotation about axis 0 by ``angle * (i + 0.5) / N1`` -- the structure turns by
    ``angle`` along axis 0;
  - ``bend``: rotation about axis 2 by ``angle * ((j + 0.5) / N2 - 0.5)`` -- the structure's
    direction in the (i, j) plane sweeps ``angle`` across axis 1, as in a bent bar;
  - ``radial``: exemplar axis 0 points away from the volume's central axis (the line through the
    centre along axis 0) and exemplar axis 2 along axis 0 -- concentric shells (``angle`` unused);
* a direction field ``(N1, N2, N3, 3)``: the exemplar's axis 0 is turned onto the direction by the
  smallest rotation (Rodrigues' formula; the paper's "vector field"); a zero vector keeps the
  exemplar's orientation, and a field that is zero everywhere (it would change nothing) is
  refused, as are NaN and Inf;
* a frame field ``(N1, N2, N3, 3, 3)``: its rotation part (polar decomposition by SVD, so any
  scaling is removed, as the paper's ``w~(D) = w(D) / ||w(D)||``);
* a ``.npy`` file holding either array.

:func:`level_frames` gives the field at a pyramid level: a named field evaluated at the level's
voxel centres, an array field sampled at every ``2**level``-th voxel.
"""

from __future__ import annotations

import os

import numpy as np

from .. import _validation as check
from ..io.files import read_array

__all__ = ["FIELDS", "as_frames", "field_input", "level_frames", "rotation_about", "rotation_onto"]

#: The named analytic fields.
FIELDS = ("none", "twist", "bend", "radial")


def rotation_about(axis: int, theta: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` by angles ``theta`` (radians) about coordinate ``axis``
    (right-handed in the order of the axes: about 0 turns axis 1 towards axis 2)."""
    theta = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros(theta.shape + (3, 3))
    a, b = [x for x in range(3) if x != axis]
    out[..., axis, axis] = 1.0
    out[..., a, a] = c
    out[..., b, b] = c
    out[..., b, a] = s
    out[..., a, b] = -s
    return out


def rotation_onto(directions: np.ndarray) -> np.ndarray:
    """Smallest rotations ``(..., 3, 3)`` turning axis 0 onto each direction ``(..., 3)``
    (zero vectors: the identity; exactly opposite: half a turn about axis 1)."""
    d = np.asarray(directions, dtype=np.float64)
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    unit = np.where(norm > 0, d / np.where(norm > 0, norm, 1.0), np.array([1.0, 0.0, 0.0]))
    e0 = np.array([1.0, 0.0, 0.0])
    v = np.cross(np.broadcast_to(e0, unit.shape), unit)
    c = unit[..., 0]
    vx = np.zeros(unit.shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2] = -v[..., 2], v[..., 1]
    vx[..., 1, 0], vx[..., 1, 2] = v[..., 2], -v[..., 0]
    vx[..., 2, 0], vx[..., 2, 1] = -v[..., 1], v[..., 0]
    opposite = c < -1 + 1e-9
    scale = np.where(opposite, 0.0, 1.0 / np.where(opposite, 1.0, 1.0 + c))
    out = np.eye(3) + vx + (vx @ vx) * scale[..., None, None]
    out[opposite] = np.diag([-1.0, 1.0, -1.0])
    return out


def as_frames(array, size: tuple[int, int, int], *, name: str = "vector_field") -> np.ndarray:
    """Validate a direction ``(N1, N2, N3, 3)`` or frame ``(N1, N2, N3, 3, 3)`` field of the
    output ``size`` and return its rotations ``(N1, N2, N3, 3, 3)`` float32."""
    a = np.asarray(array)
    if a.dtype == object or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        check.fail(f"{name} must hold real numbers; got dtype {a.dtype}")
    size = tuple(size)
    if a.shape not in (size + (3,), size + (3, 3)):
        check.fail(f"{name} must have shape {size + (3,)} (a direction per voxel) or "
                   f"{size + (3, 3)} (a frame per voxel) for a volume of size {size}; got {a.shape}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        check.fail(f"{name} contains {int((~np.isfinite(a)).sum())} NaN or Inf values; a field "
                   f"needs a finite direction or frame at every voxel")
    if not a.any():
        check.fail(f"{name} is zero everywhere, which turns nothing (a zero vector keeps the "
                   f"exemplar's orientation); give non-zero directions or frames, or no field")
    if a.ndim == 4:
        return rotation_onto(a).astype(np.float32)
    u, _, vt = np.linalg.svd(a)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if flip.any():
        u[flip, :, -1] *= -1
        r = u @ vt
    return np.ascontiguousarray(r, dtype=np.float32)


def field_input(field, size: tuple[int, int, int]) -> tuple[str, np.ndarray | None]:
    """(name recorded in the configuration, frames array or None) for a ``vector_field`` value:
    a name of :data:`FIELDS`, an array, or a ``.npy`` file path."""
    if field is None:
        return "none", None
    if isinstance(field, str) and field.lower() in FIELDS:
        return field.lower(), None
    if isinstance(field, (str, os.PathLike)):
        if not str(field).lower().endswith(".npy"):
            check.fail(f"vector_field must be one of {', '.join(FIELDS)} or a .npy file; got {field!r}")
        return f"file:{os.fspath(field)}", as_frames(read_array(field, what="vector field file"), size,
                                                     name=f"vector_field file '{os.fspath(field)}'")
    return "array", as_frames(field, size)


def level_frames(name: str, frames: np.ndarray | None, size: tuple[int, int, int], level: int,
                 angle: float) -> np.ndarray:
    """The frames of pyramid ``level`` (0 = finest): ``(n1, n2, n3, 3, 3)`` float32, or
    ``(1, 1, 1, 3, 3)`` for the identity field."""
    f = 2 ** level
    shape = tuple(n // f for n in size)
    if frames is not None:
        return np.ascontiguousarray(frames[f // 2::f, f // 2::f, f // 2::f][:shape[0], :shape[1], :shape[2]])
    if name == "none":
        return np.eye(3, dtype=np.float32).reshape(1, 1, 1, 3, 3)
    centres = [(np.arange(n) + 0.5) / n for n in shape]
    i, j, k = np.meshgrid(*centres, indexing="ij")
    theta = np.deg2rad(angle)
    if name == "twist":
        r = rotation_about(0, theta * i)
    elif name == "bend":
        r = rotation_about(2, theta * (j - 0.5))
    else:  # radial
        phi = np.arctan2(k - 0.5, j - 0.5)
        r = np.zeros(shape + (3, 3))
        r[..., 1, 0], r[..., 2, 0] = np.cos(phi), np.sin(phi)
        r[..., 1, 1], r[..., 2, 1] = -np.sin(phi), np.cos(phi)
        r[..., 0, 2] = 1.0
    return np.ascontiguousarray(r, dtype=np.float32)
