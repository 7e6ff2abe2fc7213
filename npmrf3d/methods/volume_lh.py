"""Synthesis from a 3D exemplar with a vector-field deformation (the vector-field deformation method, IET Image Processing 2012).

Why a module of ~640 lines: configuration, validation, the appearance-space model, the
coordinate pyramid's side of the shared level loop (:class:`CoordinateLevels`) and the registry
entry of one method, most of it the documented signature.

The method (registry name ``volume-lh``: it is Lefebvre & Hoppe's appearance-space, coordinate
pyramid synthesis carried to 3D, as the vector-field deformation method does) makes a volume whose every voxel *copies* a
voxel of the 3D exemplar: the synthesised volume is a field of exemplar coordinates ``S``.

1. **Appearance space** (per level): the exemplar, Gaussian-smoothed for the level's spacing
   ``h = 2**level`` (``sigma = h / 2``, none at the finest level), gives every voxel the vector of
   its ``5 x 5 x 5`` neighbourhood sampled every ``h`` voxels (``125 C`` values, borders clamped);
   PCA keeps ``pca_dims`` = 8 dimensions (the paper: 375 -> 8).
2. **Similarity sets** (``k = 3``): the voxel itself, then the nearest voxels in appearance space
   with each new one outside the ``7 x 7 x 7`` neighbourhood (``exclude = 3``) of the earlier ones.
3. **Coordinate pyramid**: the coarsest level starts from the exemplar tiled at its spacing
   with a random offset of its own for every tile, and jitter (``start = "blocks"``;
   ``"tiled"``: one offset for all, what the paper's pyramid from one voxel gives, which
   repeats the exemplar at its period; ``"random"``: uniform coordinates);
   each level's children take ``S[parent] + floor(h R^T (delta - 1/2) + 1/2)`` (``delta`` in
   {0, 1}^3, ``R`` the child's frame), then a **jitter** ``floor(h r U + 1/2)``, ``U`` uniform in
   [-1, 1]^3 (``r = jitter``, the paper's 0.7), then ``passes`` **correction** passes of 8
   parity sub-passes (:func:`npmrf3d._kernels.volume_lh.correct`).
4. **Deformation**: every voxel has a frame ``R`` (:mod:`npmrf3d.model.fields`); the neighbourhood of a
   voxel ``p`` is read at the warped positions ``p + floor(R D + 1/2)`` of the 8 diagonals ``D``,
   and compared with the exemplar's at ``u + h D``, so exemplar direction ``D`` is laid along
   ``R D``: the structure turns with the field.

Choices where the paper is silent (also in ``docs/volume.md``, "The method and its settings"): a coarsest level of
``size / 2**(levels-1)`` voxels holding the exemplar tiled at its spacing (what one voxel
up-sampled would give) with a random offset per tile and jitter; the valid box keeps
coordinates ``window // 2`` voxels from the exemplar's faces (the paper discards 2 voxels per
border); coordinates are rounded after up-sampling and jitter; the similarity sets are searched
(exact ``cKDTree``) for and among the valid voxels of a stride-2 lattice (1/8 of them), the
exclusion rule applied to all earlier members, and the other voxels take their lattice voxel's
set shifted by their offset; the correction keeps the current coordinate as a candidate
and reads the sub-pass's input (Jacobi), so results do not depend on the thread count; a position
histogram (``usage``, this project's addition after Chen & Wang 2010: :func:`cell_usage`) keeps
non-stationary exemplars from collapsing onto one homogeneous region; the output is toroidal;
colours are the exemplar's full-resolution values at the final coordinates.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .. import _validation as check
from .._kernels import _jit
from .._kernels import volume_lh as _k
from ..analysis.repetition import copy_repetition
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..io.checkpoints import run_key
from ..model.exemplar3d import load_volume_exemplar, volume_fits
from ..model.fields import FIELDS, field_input, level_frames
from ..model.phases import (
    MAX_PHASES,
    PhaseControl,
    phase_error,
    phase_footprint,
    phase_membership,
)
from ..model.pyramid import ArraySpec, Levels, run_pyramid
from ..resources import Estimate
from ..options import given_options, option, refuse_inapplicable
from ._api import prepare

__all__ = ["VolumeConfig", "appearance_space", "make_volume_config", "run", "similarity_sets",
           "volume_synthesize"]

ProgressCallback = Callable[[int, int, int, float], None]
#: Exemplar voxels sampled to compute the PCA of each level.
PCA_SAMPLES = 20000
#: Stride of the lattice the similarity sets are searched in, and the neighbours queried.
SET_STRIDE = 2
SET_QUERY = 48
#: How the coarsest level starts: the exemplar tiled (the paper's coordinate pyramid, from one
#: voxel) with a random offset and jitter, uniformly random coordinates, or the tiling with an
#: offset of its own for every tile.
STARTS = ("tiled", "random", "blocks")
#: The synthesis neighbourhoods: the paper's 8 diagonal neighbours, or those and the 6 faces.
NEIGHBOURHOODS = {"diagonal": _k.DIAGONALS, "faces": np.concatenate([_k.DIAGONALS, _k.FACES])}


@dataclass(frozen=True)
class VolumeConfig:
    """A validated run of the 3D-exemplar method; every default lives here."""

    size: tuple[int, int, int] = option((DEFAULT_SIZE,) * 3, "output size", kind="own")
    levels: int = option(4, "pyramid levels; the coarsest has size / 2**(levels-1) voxels per side", kind="int",
                         low=1, high=6, metavar="L")
    window: int = option(5, "side of the appearance-space neighbourhoods, odd, 3 to 7 (the paper: 5)",
                         kind="int", metavar="W")
    pca_dims: int = option(8, "appearance-space dimensions kept by PCA (the paper: 8)", kind="int", low=1,
                           high=64)
    k: int = option(3, "size of the similarity sets (the paper: 3)", kind="int", low=1, high=16)
    exclude: int = option(3, "later similarity-set members lie farther than this many voxels from earlier "
                          "ones (the paper: 3)", kind="int", low=0, high=16)
    passes: int = option(4, "correction passes per level, each of 8 parity sub-passes", kind="int", low=0,
                         high=16)
    neighbourhood: str = option("faces", "synthesis neighbourhood: diagonal (the paper's 8 diagonal "
                                "neighbours) or faces (those and the 6 face neighbours)", kind="choice",
                                choices=lambda: tuple(NEIGHBOURHOODS))
    jitter: float = option(0.7, "jitter at the coarser levels, in units of the level's spacing (the paper: "
                           "0.7)", kind="real", low=0.0, high=4.0)
    fine_jitter: float = option(0.0, "jitter at the finest level", kind="real", low=0.0, high=4.0)
    usage: float = option(1.0, "position histogram: a candidate copying an over-used part of the exemplar "
                          "pays per excess use (0: the paper's rule)", kind="real", low=0.0, high=100.0)
    balance: float = option(4.0, "phase histogram: a candidate of a phase the volume over-holds pays per "
                            "excess share (0: the phase fractions drift)", kind="real", low=0.0, high=100.0)
    # docs/volume.md, "The coarsest level's start": the tiled start repeats 8-22 % of a 128^3 volume at the
    # exemplar's period; blocks keeps the statistics of 6 scans x 3 seeds but one surface area
    start: str = option("blocks", "the coarsest level: blocks (the exemplar tiled, each tile offset), tiled "
                        "(one offset: repeats at the exemplar's period) or random", kind="choice",
                        choices=STARTS)
    vector_field: str = option("none", "deformation", kind="own")
    angle: float = option(180.0, "degrees of rotation of the named fields twist and bend", kind="real",
                          low=-3600.0, high=3600.0,
                          applies=lambda config: config.vector_field in ("twist", "bend"),
                          needs="vector_field is twist or bend")
    seed: int | None = option(None, "random seed", kind="own")

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary."""
        return asdict(self)


DEFAULTS = VolumeConfig()


def make_volume_config(*, size=DEFAULTS.size, levels=DEFAULTS.levels, window=DEFAULTS.window,
                       pca_dims=DEFAULTS.pca_dims, k=DEFAULTS.k, exclude=DEFAULTS.exclude,
                       passes=DEFAULTS.passes, neighbourhood=DEFAULTS.neighbourhood,
                       jitter=DEFAULTS.jitter, fine_jitter=DEFAULTS.fine_jitter,
                       usage=DEFAULTS.usage, balance=DEFAULTS.balance, start=DEFAULTS.start,
                       vector_field=DEFAULTS.vector_field, angle=DEFAULTS.angle,
                       seed=None) -> VolumeConfig:
    """Validate plain keyword arguments into a frozen :class:`VolumeConfig` (``vector_field``: a
    name of :data:`npmrf3d.model.fields.FIELDS`, ``array`` or ``file:PATH`` as :func:`field_input`
    records it)."""
    levels = check.integer("levels", levels, low=1, high=6)
    dims = check.size(size, levels=levels, coarsest=2)
    window = check.integer("window", window, low=3, high=7)
    if window % 2 == 0:
        check.fail(f"window must be odd; got {window}")
    if not isinstance(vector_field, str) or not (vector_field in FIELDS or vector_field == "array"
                                                 or vector_field.startswith("file:")):
        check.fail(f"vector_field must be one of {', '.join(FIELDS)}, an array or a .npy file; "
                   f"got {vector_field!r}")
    if seed is not None:
        seed = check.integer("seed", seed, low=0)
    return VolumeConfig(
        size=dims, levels=levels, window=window,
        pca_dims=check.integer("pca_dims", pca_dims, low=1, high=64),
        k=check.integer("k", k, low=1, high=16), exclude=check.integer("exclude", exclude, low=0, high=16),
        passes=check.integer("passes", passes, low=0, high=16),
        neighbourhood=check.choice("neighbourhood", neighbourhood, tuple(NEIGHBOURHOODS)),
        jitter=check.real("jitter", jitter, low=0.0, high=4.0),
        fine_jitter=check.real("fine_jitter", fine_jitter, low=0.0, high=4.0),
        usage=check.real("usage", usage, low=0.0, high=100.0),
        balance=check.real("balance", balance, low=0.0, high=100.0),
        start=check.choice("start", start, STARTS),
        vector_field=vector_field, angle=check.real("angle", angle, low=-3600.0, high=3600.0), seed=seed)


# --------------------------------------------------------------------------- the exemplar model


def appearance_space(exemplar: np.ndarray, level: int, window: int, dims: int,
                     rng: np.random.Generator) -> np.ndarray:
    """The appearance-space exemplar of one level: ``(D, H, W, dims)`` float64.

    Each voxel's ``window^3`` neighbourhood, sampled every ``h = 2**level`` voxels in the exemplar
    smoothed by a Gaussian of ``sigma = h / 2`` (none at level 0), borders clamped, projected on
    the ``dims`` leading principal directions of :data:`PCA_SAMPLES` random voxels' vectors
    (the scatter matrix a product of two copies of the centred vectors: not
    :func:`npmrf3d.model.kcoherence.pca_project`, whose one-array product differs in the last
    bits).
    """
    h = 2 ** level
    ex = smoothed(exemplar, level)
    shape = ex.shape[:3]
    r = window // 2
    offsets = [(a, b, c) for a in range(-r, r + 1) for b in range(-r, r + 1) for c in range(-r, r + 1)]
    n = shape[0] * shape[1] * shape[2]
    sample = np.sort(rng.choice(n, size=min(n, PCA_SAMPLES), replace=False))
    pos = np.stack(np.unravel_index(sample, shape), axis=1)
    vectors = np.concatenate([ex[tuple(np.clip(pos[:, a] + h * o[a], 0, shape[a] - 1) for a in range(3))]
                              for o in offsets], axis=1)
    mean = vectors.mean(axis=0)
    _, vecs = np.linalg.eigh((vectors - mean).T @ (vectors - mean))
    basis = vecs[:, ::-1][:, :min(dims, vectors.shape[1])]
    out = np.empty(shape + (basis.shape[1],))
    _k.project(np.ascontiguousarray(ex), h, r, mean, np.ascontiguousarray(basis), out)
    return out


def similarity_sets(feat: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int, exclude: int) -> np.ndarray:
    """``(D * H * W, k)`` int64 flat indices: row ``q`` is the similarity set of valid voxel ``q``
    (itself first; rows of voxels outside the valid box hold the voxel itself).

    The sets are searched for the valid voxels of a lattice of stride :data:`SET_STRIDE` (exact
    ``cKDTree`` over the lattice, :data:`SET_QUERY` nearest, then the exclusion rule,
    :func:`npmrf3d._kernels.volume_lh.similarity_sets`); every other valid voxel takes its lattice
    voxel's set shifted by its offset from it (a coherent shift), clamped to the valid box.
    """
    shape = feat.shape[:3]
    flat_all = np.arange(shape[0] * shape[1] * shape[2], dtype=np.int64)
    out = np.repeat(flat_all[:, None], k, axis=1)
    if k == 1:
        return out
    axes = [np.arange(lo[a], hi[a] + 1) for a in range(3)]
    lattice = np.stack(np.meshgrid(*[x[::SET_STRIDE] for x in axes], indexing="ij"), axis=-1).reshape(-1, 3)
    points = feat[tuple(lattice.T)]
    m = min(len(lattice), SET_QUERY)
    _, idx = cKDTree(points).query(points, k=m, workers=_jit.thread_count())
    idx = np.asarray(idx, dtype=np.int64).reshape(len(lattice), m)
    # a point's own row first (exact duplicates could come back in another order)
    own = np.arange(len(lattice))
    idx = np.concatenate([own[:, None], np.where(idx == own[:, None], own[:, None], idx)], axis=1)
    sets = np.empty((len(lattice), k), dtype=np.int64)
    _k.similarity_sets(idx, lattice.astype(np.int64), k, exclude, sets)
    members = lattice[sets]  # (L, k, 3) positions
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    rep = lo + (grid - lo) // SET_STRIDE * SET_STRIDE
    steps = [len(x[::SET_STRIDE]) for x in axes]
    row = np.ravel_multi_index(tuple(((rep - lo) // SET_STRIDE).T), steps)
    shifted = np.clip(members[row] + (grid - rep)[:, None, :], lo, hi)
    shifted[:, 0] = grid
    out[np.ravel_multi_index(tuple(grid.T), shape)] = np.ravel_multi_index(
        tuple(shifted.reshape(-1, 3).T), shape).reshape(-1, k)
    return out


def _valid_box(shape, window: int) -> tuple[np.ndarray, np.ndarray]:
    r = window // 2
    return np.full(3, r, dtype=np.int64), np.array([n - 1 - r for n in shape], dtype=np.int64)


# --------------------------------------------------------------------------- the pyramid


def upsample(coords: np.ndarray, frames: np.ndarray, h: int, lo, hi) -> np.ndarray:
    """Children's coordinates ``S[parent] + floor(h R^T (delta - 1/2) + 1/2)``, clamped to the
    valid box (``frames``: the children's, or one frame for all)."""
    n1, n2, n3 = coords.shape[:3]
    child = np.repeat(np.repeat(np.repeat(coords, 2, axis=0), 2, axis=1), 2, axis=2).astype(np.int64)
    delta = np.stack(np.meshgrid(*[(np.arange(2 * n) % 2) - 0.5 for n in (n1, n2, n3)], indexing="ij"), axis=-1)
    rt = np.swapaxes(frames.astype(np.float64), -1, -2)
    offset = np.floor(h * np.einsum("...rc,...c->...r", rt, delta) + 0.5).astype(np.int64)
    return np.clip(child + offset, lo, hi)


def initial_coordinates(shape, h: int, lo, hi, start: str, jitter: float,
                        rng: np.random.Generator) -> np.ndarray:
    """The coarsest level's coordinates ``(*shape, 3)`` int64 in the valid box ``[lo, hi]``.

    ``tiled``: the exemplar laid out at the level's spacing, ``lo + (h p + o) mod (hi - lo + 1)``
    with one random offset ``o``, then jittered (:func:`jittered`, amplitude ``jitter``) — what the
    paper's pyramid from a single voxel gives, with wrap-around seams for the correction to mend.
    ``random``: every coordinate uniform in the box (the exemplar's parts mixed voxel by voxel,
    from which the correction drifts to the parts easiest to match: ``docs/volume.md``).
    ``blocks``: the tiling, but every tile (``extent // h`` coarse voxels per axis) takes its own
    random offset, so no block of the exemplar repeats at one shift."""
    lo, hi = np.asarray(lo, dtype=np.int64), np.asarray(hi, dtype=np.int64)
    if start == "random":
        return np.stack([rng.integers(lo[a], hi[a] + 1, size=shape) for a in range(3)], axis=-1)
    extent = hi - lo + 1
    grid = np.stack(np.meshgrid(*[np.arange(n, dtype=np.int64) for n in shape], indexing="ij"), axis=-1)
    if start == "blocks":
        tile = np.maximum(1, extent // h)  # coarse voxels per exemplar tile, per axis
        blocks = tuple(int(-(-n // t)) for n, t in zip(shape, tile))
        offsets = rng.integers(0, extent, size=blocks + (3,))
        offset = offsets[tuple((grid // tile)[..., a] for a in range(3))]
    else:
        offset = rng.integers(0, extent)
    uniforms = rng.uniform(-1.0, 1.0, size=tuple(shape) + (3,)).astype(np.float32)
    return jittered(lo + (grid * h + offset) % extent, h, jitter, uniforms, lo, hi)


def jittered(coords: np.ndarray, h: int, amount: float, uniforms: np.ndarray, lo, hi) -> np.ndarray:
    """``S + floor(h * amount * U + 1/2)`` clamped to the valid box (``U`` pre-drawn in [-1, 1])."""
    return np.clip(coords + np.floor(h * amount * uniforms + 0.5).astype(np.int64), lo, hi)


def correction_pass(coords: np.ndarray, frames: np.ndarray, feat: np.ndarray, kset: np.ndarray,
                    h: int, lo, hi, offsets: np.ndarray = _k.DIAGONALS,
                    usage: float = 0.0, balance: float = 0.0,
                    phases: tuple[np.ndarray, np.ndarray] | None = None,
                    control: PhaseControl | None = None) -> tuple[np.ndarray, float]:
    """One correction pass: the 8 parity sub-passes in a fixed order; returns the coordinates and
    the mean matching score.

    A sub-pass reads ``coords`` and writes its parity class into ``out``, which is then copied
    back into ``coords`` (an eighth of the voxels), so every sub-pass reads its input unchanged.
    ``usage`` is the strength of the position histogram (:func:`cell_usage`), recounted before
    every sub-pass; 0 is the paper's rule. ``balance`` is the strength of the phase histogram
    (:func:`npmrf3d.model.phases.class_balance`, of ``phases = (phase_footprint(...),
    share)``), also recounted before every sub-pass; ``control``
    (:class:`npmrf3d.model.phases.PhaseControl`, ``PhaseControl.start(phases)`` at the start
    of a run) holds its prices and gain, is **updated in place** every sub-pass and is carried
    from pass to pass and level to level."""
    coords = np.array(coords, dtype=np.int64, order="C")  # a copy: the caller's array stays
    out = np.empty_like(coords)
    feat = np.ascontiguousarray(feat)
    positions = set_positions(kset, feat.shape[:3])
    cost = np.zeros(coords.shape[:3])
    scale = usage_scale(feat, offsets) if usage or balance else 0.0
    weight = float(usage) * scale
    counts, even = np.zeros((1, 1, 1)), 1.0  # read only when weight > 0
    bias = np.zeros((1, 1, 1))  # none
    if balance and (phases is None or control is None):
        check.fail("balance > 0 needs the exemplar's phases and their control state "
                   "(phases=(phase_footprint(...), share), control=PhaseControl.start(len(share)))")
    for parity in np.ndindex(2, 2, 2):
        if weight:
            counts, even = cell_usage(coords, feat.shape[:3], h, lo, hi)
        if balance:
            control.step(phase_error(coords, *phases))
            bias = control.cost(phases[0], float(balance) * scale)
        _k.correct(coords, out, frames, feat, positions, h, lo, hi, offsets,
                   np.array(parity, dtype=np.int64), cost, counts, even, weight, bias)
        cls = tuple(slice(p, None, 2) for p in parity)
        coords[cls] = out[cls]
    return coords, float(cost.mean())


def usage_scale(feat: np.ndarray, offsets: np.ndarray) -> float:
    """The distance scale of the position-histogram penalty: half the expected matching distance
    of two random exemplar voxels, ``len(offsets) * sum_e var(feat[..., e])``."""
    return float(len(offsets) * feat.reshape(-1, feat.shape[-1]).var(axis=0).sum())


def cell_usage(coords: np.ndarray, shape, h: int, lo, hi) -> tuple[np.ndarray, float]:
    """The position histogram of a level: how many voxels' coordinates fall in each ``h``-cell
    ``u // h`` of the exemplar (float64, ``ceil(shape / h)``), and ``even``, the count of every
    cell that meets the valid box if all were used equally.

    This project's addition after Chen & Wang 2010's position histogram (the vector-field deformation method has none, and
    relies on a stationary exemplar): the correction adds ``usage * s * max(0, c / even - 1)`` to
    a candidate's distance (``s``: :func:`usage_scale`), so that no part of the exemplar is
    copied far more often than the rest. Without it a non-stationary exemplar (a scan with a
    homogeneous region) collapses onto that region: uniform neighbourhoods match each other best
    (``docs/volume.md``). Cells of the level's spacing make ``even`` the same at every level,
    the ratio of output voxels to exemplar voxels."""
    cells = tuple(-(-int(n) // h) for n in shape)
    flat = np.ravel_multi_index(tuple((coords.reshape(-1, 3) // h).T), cells)
    counts = np.bincount(flat, minlength=int(np.prod(cells))).astype(np.float64).reshape(cells)
    valid = int(np.prod([int(hi[a]) // h - int(lo[a]) // h + 1 for a in range(3)]))
    return counts, coords[..., 0].size / valid


def set_positions(kset: np.ndarray, shape) -> np.ndarray:
    """The similarity sets ``(D * H * W, k)`` of flat indices as positions ``(D * H * W, k, 3)``
    int64, the form :func:`npmrf3d._kernels.volume_lh.correct` reads."""
    return np.ascontiguousarray(np.stack(np.unravel_index(kset, tuple(shape)), axis=-1), dtype=np.int64)


def smoothed(exemplar: np.ndarray, level: int) -> np.ndarray:
    """The exemplar of a level: Gaussian-smoothed by ``sigma = 2**level / 2`` (none at level 0),
    float64, borders by nearest values (as :func:`appearance_space` sees it)."""
    h = 2 ** level
    ex = exemplar.astype(np.float64)
    if h > 1:
        ex = ndimage.gaussian_filter(ex, sigma=(h / 2, h / 2, h / 2, 0), mode="nearest")
    return np.ascontiguousarray(ex)


def window_offsets(window: int) -> np.ndarray:
    """The ``window^3 - 1`` offsets of a cube without its centre, lexicographic."""
    r = window // 2
    return np.array([o for o in np.ndindex(window, window, window) if o != (r, r, r)], dtype=np.int64) - r


def parzen_pass(coords, frames, feat, values, kset, h: int, lo, hi, offsets, window: int,
                adaptive: float, centre_h2: float) -> tuple[np.ndarray, float]:
    """:func:`correction_pass` with the Parzen decision (:func:`_kernels.volume.correct_parzen`)."""
    coords = np.ascontiguousarray(coords, dtype=np.int64)
    cost = np.zeros(coords.shape[:3])
    woff = window_offsets(window)
    for parity in np.ndindex(2, 2, 2):
        out = coords.copy()
        _k.correct_parzen(coords, out, frames, feat, values, kset, h, lo, hi, offsets, woff,
                          np.array(parity, dtype=np.int64), adaptive, centre_h2, cost)
        coords = out
    return coords, float(cost.mean())


# --------------------------------------------------------------------------- public


def volume_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress: ProgressCallback | None = None,
                      checkpoint: str | Path | None = None, exemplars=None, exemplar_kind: str = "auto",
                      spacing=None, **options) -> SynthesisResult:
    """Synthesise a volume from a 3D exemplar, optionally deformed by a vector field.

    Parameters
    ----------
    exemplar : path or (D, H, W) / (D, H, W, C) array
        The 3D exemplar (``.npy``, TIFF stack); see :func:`npmrf3d.model.exemplar3d.load_volume_exemplar`.
    size : int or (N1, N2, N3)
        Output size, divisible by ``2**(levels - 1)``.
    levels : int
        Pyramid levels; the coarsest has ``size / 2**(levels - 1)`` voxels per side and spacing
        ``2**(levels - 1)`` in exemplar coordinates.
    window : odd int
        Side of the appearance-space neighbourhoods (the paper's m = 5).
    pca_dims : int
        Appearance-space dimensions (the paper: 8).
    k : int
        Size of the similarity sets (the paper: 3).
    exclude : int
        Later similarity-set members lie farther than this (Chebyshev) from earlier ones (the
        paper's n = 7, i.e. 3).
    passes : int
        Correction passes per level (8 parity sub-passes each).
    neighbourhood : {"faces", "diagonal"}
        The synthesis neighbourhood: the paper's 8 diagonal neighbours (``diagonal``), or those
        and the 6 face neighbours (``faces``, the default: the diagonals alone split the grid into
        four sub-lattices that drift apart, measured in ``docs/volume.md``).
    jitter : float
        Jitter amplitude ``r`` in units of the level's spacing at the coarser levels (the
        paper: 0.7).
    fine_jitter : float
        Jitter amplitude at the finest level (0: none, chosen by measurement, docs/volume.md).
    usage : float
        Strength of the position histogram (:func:`cell_usage`): ``usage * s * max(0, c / even -
        1)`` is added to a candidate's distance, ``c`` the voxels already copying its exemplar
        cell, ``s`` half the distance of two random exemplar neighbourhoods. 0 is the paper's rule, which collapses onto one homogeneous region of a
        non-stationary scan (``docs/volume.md``).
    balance : float
        Strength of the phase histogram (:mod:`npmrf3d.model.phases`): a candidate whose
        phase (a segmented exemplar's value, or a side of a grey one's Otsu threshold) the
        volume already holds more often than the exemplar pays ``balance * g * s * (max(0,
        share / exemplar share - 1) + price)``, the price summing that relative error over the
        sub-passes, the gain ``g`` halved when the error flips sign between sub-passes (a
        noisy exemplar's oscillation) and grown back otherwise; at the coarser levels a
        coordinate counts as the phase mix its descendants will copy, and a grey voxel near the
        threshold as partly both sides (:func:`npmrf3d.model.phases.phase_membership`). 0 leaves the phase
        fractions free (a minority phase such as the pores of a rock then shrinks level by
        level).
    start : {"tiled", "random", "blocks"}
        The coarsest level: the exemplar tiled at its spacing with a random offset and jitter
        (the paper's pyramid, which repeats the exemplar at its period), uniformly random
        coordinates, or (the default) the tiling with an offset of its own for every tile (no
        block of the exemplar repeated at one shift).
    vector_field : str, path or array
        ``none``, ``twist``, ``bend``, ``radial`` (:mod:`npmrf3d.model.fields`), a ``.npy`` file, or an
        array: directions ``(N1, N2, N3, 3)`` or frames ``(N1, N2, N3, 3, 3)``.
    angle : float
        Degrees of rotation of the named fields ``twist`` and ``bend``.
    exemplar_kind : {"auto", "volume"}
        ``volume`` reads a 3-D array whose last axis is at most 4 as a volume.
    spacing : float or (z, y, x), optional
        Voxel size of the exemplar; must be isotropic.
    rng : None, int or numpy Generator
        Seed; the result depends on it only (not on the number of threads).
    progress : callable, optional
        ``progress(level, pass, passes, mean distance)``; pass 0 at the start of each level.
    checkpoint : path, optional
        ``.npz`` file written after each level; a matching one is resumed from.

    Returns
    -------
    SynthesisResult
        ``volume`` (N1, N2, N3, C) float32 exemplar values; ``history`` the mean matching distance
        per pass, per level; ``stats`` per level: shape, spacing, model seconds, PCA dimensions.

    Examples
    --------
    >>> layers = np.tile((np.arange(20) // 2 % 2).astype(np.float32)[:, None, None], (1, 20, 20))
    >>> res = volume_synthesize(layers, size=16, levels=2, rng=0)
    >>> res.volume.shape, sorted(np.unique(res.volume).tolist())
    ((16, 16, 16, 1), [0.0, 1.0])
    """
    t_start = time.perf_counter()
    levels = check.integer("levels", options.get("levels", DEFAULTS.levels), low=1, high=6)
    field_name, field_array = field_input(options.get("vector_field", DEFAULTS.vector_field),
                                          check.size(size, levels=levels, coarsest=2))
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint,
                                          options={**options, "vector_field": field_name},
                                          load=volume_loader(exemplar_kind, spacing))
    refuse_inapplicable(config, given_options(VolumeConfig, options))
    return run(per_view, config, generator, progress=progress, checkpoint=checkpoint,
               t_start=t_start, vector_field=field_array)


def volume_loader(exemplar_kind: str, spacing):
    """The exemplar loader of the 3D-exemplar methods for :func:`npmrf3d.methods._api.prepare`:
    one 3D exemplar (``exemplar_kind`` and ``spacing`` as
    :func:`npmrf3d.model.exemplar3d.load_volume_exemplar`), no per-view exemplars."""

    def load(exemplar, exemplars, config) -> dict:
        if exemplars:
            check.fail("a 3D exemplar is one volume for every direction: per-view exemplars are "
                       "for the 2D methods")
        if exemplar is None:
            check.fail("this method needs a 3D exemplar (a .npy or .npz volume, a TIFF stack, or "
                       "a (D, H, W) or (D, H, W, C) array); no 3D exemplar is bundled")
        return {"volume": load_volume_exemplar(exemplar, exemplar_kind=exemplar_kind, spacing=spacing)}

    return load


def run(per_view, config: VolumeConfig, rng: np.random.Generator, *,
        progress: ProgressCallback | None = None, checkpoint: str | Path | None = None,
        t_start: float | None = None, vector_field: np.ndarray | None = None,
        parzen: tuple[float, float] | None = None) -> SynthesisResult:
    """The method on a validated configuration and ``{"volume": (D, H, W, C) float32}``.

    ``parzen = (adaptive, centre_bandwidth)`` decides every correction by the Parzen LCPDF of
    full ``window^3`` neighbourhoods of the level's smoothed exemplar values
    (:func:`npmrf3d._kernels.volume_lh.correct_parzen`; the ``npmrf-3d`` method,
    :mod:`npmrf3d.methods.npmrf_3d`); None: the nearest candidate in appearance space."""
    t_start = time.perf_counter() if t_start is None else t_start
    exemplar = _exemplar(per_view, config)
    if config.vector_field in ("array",) or config.vector_field.startswith("file:"):
        if vector_field is None:
            _, vector_field = field_input(config.vector_field[5:], config.size) if \
                config.vector_field.startswith("file:") else (None, None)
        if vector_field is None:
            check.fail("vector_field 'array' needs the frames array (vector_field=...)")
    levels = CoordinateLevels(config, exemplar, vector_field, parzen)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint, t_start=t_start)
    coords, timings, stats = out.state, out.timings, out.stats
    volume = np.ascontiguousarray(exemplar[coords[..., 0], coords[..., 1], coords[..., 2]], dtype=np.float32)
    t0 = time.perf_counter()
    stats["repetition"] = copy_repetition(coords)
    timings["repetition"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    labels = np.unique(exemplar.reshape(-1, exemplar.shape[3]), axis=0) if exemplar.size <= 1 << 22 else np.empty((0, exemplar.shape[3]))
    return SynthesisResult(volume=volume, history=out.history, config=config, timings=timings,
                           labels=labels.astype(np.float32), stats=stats)


class CoordinateLevels(Levels):
    """The coordinate pyramid's side of :func:`npmrf3d.model.pyramid.run_pyramid`: the state of a
    level is every voxel's exemplar coordinate ``(*shape, 3)`` int64.

    A level's appearance space samples its PCA voxels from ``rng`` before the level's
    coordinates are drawn, so it is built at the start of :meth:`initial` and :meth:`upsample`
    (:meth:`prepare` draws nothing). The phase control (``balance``) carries over from level to
    level; its prices go into the checkpoint with the coordinates.
    """

    def __init__(self, config: VolumeConfig, exemplar: np.ndarray, vector_field, parzen):
        self.config, self.exemplar, self.vector_field, self.parzen = config, exemplar, vector_field, parzen
        self.size, self.levels = config.size, config.levels
        self.lo, self.hi = _valid_box(exemplar.shape[:3], config.window)
        self.membership = phase_membership(exemplar, self.lo, self.hi) if config.balance else None
        self.control = None if self.membership is None else PhaseControl.start(len(self.membership[1]))
        self.sigma = float(exemplar.astype(np.float64).std()) or 1.0
        inputs = {"volume": exemplar, **({} if vector_field is None else {"vector_field": vector_field})}
        self.key = run_key("volume-lh", config, inputs, parzen=None if parzen is None else list(parzen))

    def prepare(self, level, shape):
        config, membership = self.config, self.membership
        self.level, self.shape, self.h = level, shape, 2 ** level
        self.frames = level_frames(config.vector_field, self.vector_field, config.size, level, config.angle)
        self.phases = None if membership is None else (
            phase_footprint(membership[0], len(membership[1]), self.h), membership[1])

    def _model(self, rng):
        """The level's appearance space and similarity sets (draws the PCA sample from ``rng``)."""
        t0 = time.perf_counter()
        self.feat = appearance_space(self.exemplar, self.level, self.config.window, self.config.pca_dims, rng)
        self.kset = similarity_sets(self.feat, self.lo, self.hi, self.config.k, self.config.exclude)
        self.model_seconds = time.perf_counter() - t0

    def initial(self, shape, rng):
        self._model(rng)
        return initial_coordinates(shape, self.h, self.lo, self.hi, self.config.start, self.config.jitter, rng)

    def upsample(self, coords, rng):
        self._model(rng)
        coords = upsample(coords, self.frames, self.h, self.lo, self.hi)
        uniforms = rng.uniform(-1.0, 1.0, size=self.shape + (3,)).astype(np.float32)
        jitter = self.config.jitter if self.level else self.config.fine_jitter
        return jittered(coords, self.h, jitter, uniforms, self.lo, self.hi)

    def start(self, level, coords):
        return self.config.passes, float("nan")

    def relax(self, level, coords, rng, on_step):
        config, h, lo, hi = self.config, self.h, self.lo, self.hi
        t0 = time.perf_counter()
        history = []
        values = None if self.parzen is None else smoothed(self.exemplar, level)
        for p in range(config.passes):
            if self.parzen is None:
                coords, mean_cost = correction_pass(coords, self.frames, self.feat, self.kset, h, lo, hi,
                                                    NEIGHBOURHOODS[config.neighbourhood],
                                                    usage=config.usage, balance=config.balance,
                                                    phases=self.phases, control=self.control)
            else:
                coords, mean_cost = parzen_pass(coords, self.frames, self.feat, values, self.kset, h, lo, hi,
                                                NEIGHBOURHOODS[config.neighbourhood], config.window,
                                                self.parzen[0], (self.parzen[1] * self.sigma) ** 2)
            history.append(mean_cost)
            on_step(p + 1, mean_cost)
        return coords, history, {"shape": list(self.shape), "spacing": h, "model_seconds": self.model_seconds,
                                 "correction_seconds": time.perf_counter() - t0,
                                 "pca_dims": int(self.feat.shape[3])}

    def to_arrays(self, coords):
        return {"coords": coords, "prices": np.zeros(0) if self.control is None else self.control.to_array()}

    def from_arrays(self, arrays):
        prices = np.asarray(arrays["prices"], dtype=np.float64)
        if self.control is not None and prices.size:
            self.control = PhaseControl.from_array(prices, len(self.membership[1]))
        return np.asarray(arrays["coords"], dtype=np.int64)

    def array_specs(self, level, shape):
        prices = (0,) if self.control is None else self.control.to_array().shape
        return {"coords": ArraySpec((*shape, 3), np.int64, self.lo, self.hi),
                "prices": ArraySpec(prices, np.float64)}


def _exemplar(per_view, config: VolumeConfig) -> np.ndarray:
    volume = per_view.get("volume") if isinstance(per_view, dict) else None
    if volume is None or np.ndim(volume) != 4:
        shapes = {v: np.shape(a) for v, a in dict(per_view).items()}
        check.fail(f"method volume-lh needs a 3D exemplar (D, H, W, C); got 2D exemplars {shapes}: "
                   f"give a volume (npmrf3d volume FILE) or use a 2D method")
    volume_fits(volume, window=config.window)
    return np.ascontiguousarray(volume, dtype=np.float32)


def volume_estimate(config: VolumeConfig, exemplars) -> Estimate:
    """Peak memory of a run: per output voxel the coordinates (int64 x 3, two copies while a
    sub-pass runs, three while up-sampling), the frames (9 float32, when a field is used) and
    the jitter (3 float32); per exemplar voxel the appearance space (float64 x dims, twice while
    it is built), the similarity sets (int64 x k, and as positions int64 x 3k) and the smoothed
    exemplar (float64 x C), and with the phase histogram the phases (int64), the cost (float64)
    and the phase mix (float32 x phases, counted as ``MAX_PHASES``, twice while it is built)."""
    n = int(np.prod(config.size))
    shape = next(iter(dict(exemplars).values()))
    shape = tuple(np.shape(shape)) if not isinstance(shape, tuple) else shape
    m = int(np.prod(shape[:3]))
    c = shape[3] if len(shape) > 3 else 1
    field = 0 if config.vector_field == "none" else 36 * n
    return Estimate({"coordinates": 3 * 24 * n + 12 * n + 4 * c * n, "vector field": field,
                     "exemplar model": m * (16 * config.pca_dims + 32 * config.k + 16 * c),
                     "phase histogram": m * (16 + 8 * MAX_PHASES) if config.balance else 0},
                    seconds=n / 2.0e5)


def _fit(config: VolumeConfig) -> dict:
    return {"window": config.window, "levels": config.levels, "toroidal": False, "kind": "volume"}


METHOD = SynthesisMethod(
    name="volume-lh", run=run, make_config=make_volume_config, config_class=VolumeConfig,
    synthesize=volume_synthesize, fit=_fit,
    description="from a 3D exemplar, after the vector-field deformation method (IET Image Processing 2012): "
                "appearance-space coordinate pyramid, k = 3 similarity "
                "sets, jitter and correction, vector-field deformation",
    resources=volume_estimate,
)
