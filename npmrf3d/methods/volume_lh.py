"""Synthesis from a 3D exemplar with a vector-field deformation (the vector-field deformation method, IET Image Processing 2012).

This module is the method's configuration, validation, documented signature and registry
entry; the model is in :mod:`npmrf3d.model`: the appearance space and similarity sets
(:mod:`~npmrf3d.model.volume_appearance`), the coordinate pyramid's start, up-sampling and
jitter (:mod:`~npmrf3d.model.volume_coordinates`), the correction passes
(:mod:`~npmrf3d.model.volume_correction`) and the level loop's side of it
(:class:`~npmrf3d.model.volume_levels.CoordinateLevels`).

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
histogram (``usage``, this project's addition after Chen & Wang 2010:
:func:`npmrf3d.model.volume_correction.cell_usage`) keeps
non-stationary exemplars from collapsing onto one homogeneous region; the output is toroidal;
colours are the exemplar's full-resolution values at the final coordinates.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import _validation as check
from ..analysis.repetition import copy_repetition
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..model.exemplar3d import load_volume_exemplar, volume_fits
from ..model.fields import FIELDS, field_input
from ..model.pyramid import run_pyramid
from ..model.volume_appearance import appearance_space, similarity_sets
from ..model.volume_coordinates import STARTS
from ..model.volume_correction import NEIGHBOURHOODS
from ..model.volume_levels import CoordinateLevels
from ..options import given_options, option, refuse_inapplicable
from ..resources import volume_estimate
from ._api import prepare

__all__ = ["METHOD", "STARTS", "VolumeConfig", "appearance_space", "make_volume_config", "run", "similarity_sets",
           "volume_estimate", "volume_loader", "volume_synthesize"]

ProgressCallback = Callable[[int, int, int, float], None]


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
        Strength of the position histogram (:func:`npmrf3d.model.volume_correction.cell_usage`): ``usage * s * max(0, c / even -
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


def _exemplar(per_view, config: VolumeConfig) -> np.ndarray:
    volume = per_view.get("volume") if isinstance(per_view, dict) else None
    if volume is None or np.ndim(volume) != 4:
        shapes = {v: np.shape(a) for v, a in dict(per_view).items()}
        check.fail(f"method volume-lh needs a 3D exemplar (D, H, W, C); got 2D exemplars {shapes}: "
                   f"give a volume (npmrf3d volume FILE) or use a 2D method")
    volume_fits(volume, window=config.window)
    return np.ascontiguousarray(volume, dtype=np.float32)


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
