"""Ground-truth statistics of two-phase volumes: what materials users judge a
synthesised volume by, against a real scan.

Every function takes a volume ``(N1, N2, N3)`` or ``(N1, N2, N3, C)`` (grey = mean of the
channels) and works on a *phase*: the voxels above a threshold (Otsu's by default,
:func:`npmrf3d.model.otsu.otsu_threshold`, or a number), or an indicator given directly (a bool volume).

* :func:`volume_fraction` -- share of the phase;
* :func:`two_point_correlation` along each axis is :func:`npmrf3d.analysis.metrics.two_point_correlation`;
  :func:`radial_two_point` is its orientation average (FFT autocorrelation binned by distance);
* :func:`specific_surface_area` -- interface area per unit volume, by marching cubes
  (``skimage.measure.marching_cubes`` at the threshold of the grey values, or at 0.5 of a bool
  indicator);
* :func:`chord_lengths` / :func:`chord_length_distribution` -- lengths of the runs of the phase
  along an axis;
* :func:`octant_fractions` / :func:`stationarity_warning` -- the phase's share in each octant,
  and a warning for an exemplar far from stationary;
* :func:`tortuosity` -- the tortuosity factor of the phase along an axis, computed by the optional
  ``taufactor`` package;
* :func:`percolates` -- whether the phase connects the two faces normal to each axis;
* :func:`relative_diffusivity` -- the phase's relative effective diffusivity along an axis, by a
  finite-volume solve (``scipy.sparse``) or by ``taufactor``;
* :func:`interface_density` -- phase boundaries crossed per unit length along an axis (twice it
  is the stereological specific surface area of an isotropic structure).

scikit-image (marching cubes) and taufactor are optional: ``pip install 'npmrf3d[materials]'``;
without them the two functions that need them say so. Otsu's threshold (256-bin histogram) is
the model's, the one the methods' phase histograms split by.

Imports :mod:`npmrf3d.analysis.metrics`, never the reverse.
"""

from __future__ import annotations

import importlib

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import linalg
from threadpoolctl import threadpool_limits

from .. import _validation as check
from ..model.otsu import otsu_threshold
from .metrics import two_point_correlation

__all__ = ["DIFFUSIVITY_SOLVERS", "chord_length_distribution", "chord_lengths", "interface_density",
           "octant_fractions", "percolates", "phase", "radial_two_point", "relative_diffusivity",
           "specific_surface_area", "stationarity_warning", "structure_summary", "tortuosity",
           "two_point_correlation", "volume_fraction"]

#: :func:`stationarity_warning` speaks when the phase's share differs by more than this between
#: two octants. Measured: 0.74 on the Colin27 corner block (background in one corner), 0.11 on
#: another Colin27 block, 0.12 on the porous stand-in (docs/volume.md).
OCTANT_SPREAD = 0.4


def _optional(module: str, what: str):
    """Import an optional dependency of the ``[materials]`` extra, or say how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        package = module.split(".")[0].replace("skimage", "scikit-image")
        check.fail(f"{what} needs the optional package {package}, which is not installed: "
                   f"pip install 'npmrf3d[materials]' (or pip install {package})")


def phase(volume, *, threshold="otsu") -> np.ndarray:
    """The phase indicator ``(N1, N2, N3)`` bool: grey value ``> threshold``.

    Parameters
    ----------
    volume : (N1, N2, N3) or (N1, N2, N3, C) array; a bool volume is its own indicator
    threshold : "otsu" or float
        Otsu's threshold of the grey values (:func:`otsu_threshold`) or a number in the
        volume's units.

    Examples
    --------
    >>> phase(np.array([0.1, 0.2, 0.9, 0.8]).reshape(1, 2, 2)).astype(int).tolist()
    [[[0, 0], [1, 1]]]
    """
    a = np.asarray(volume)
    if a.dtype == bool and a.ndim == 3:
        return a
    if a.ndim not in (3, 4) or a.size == 0 or not np.issubdtype(a.dtype, np.number):
        check.fail(f"volume must be a numeric (N1, N2, N3) or (N1, N2, N3, C) array; got shape "
                   f"{a.shape}, dtype {a.dtype}")
    grey = a.astype(np.float64).mean(axis=3) if a.ndim == 4 else a.astype(np.float64)
    if isinstance(threshold, str):
        check.choice("threshold", threshold, ("otsu",))
        if grey.min() == grey.max():
            return np.zeros(grey.shape, dtype=bool)
        threshold = otsu_threshold(grey)
    return grey > check.real("threshold", threshold)


def volume_fraction(volume, *, threshold="otsu") -> float:
    """Share of voxels in the phase (:func:`phase`)."""
    return float(phase(volume, threshold=threshold).mean())


def radial_two_point(volume, *, threshold="otsu", max_distance: int | None = None,
                     periodic: bool = True) -> np.ndarray:
    """Orientation-averaged two-point probability ``S2(r)`` for ``r = 0 .. max_distance``.

    ``S2(r)`` is the mean of the autocorrelation ``<I(x) I(x + d)>`` over all offsets ``d`` with
    ``round(|d|) = r`` (so ``S2(0)`` is the volume fraction). Periodic by default: the volume
    wraps around, every offset has ``N1 N2 N3`` pairs. ``periodic=False`` counts only the pairs
    inside the volume, each offset divided by its own number of pairs
    ``(N1 - |d1|)(N2 - |d2|)(N3 - |d3|)`` -- PoreSpy's ``metrics.two_point_correlation``
    (``probability_scaled``, bins ``[r - 1/2, r + 1/2)``); the one for a crop of a scan.

    Returns
    -------
    (max_distance + 1,) float64; default ``max_distance = min(shape) // 2``.
    """
    ind = phase(volume, threshold=threshold).astype(np.float64)
    r_max = min(ind.shape) // 2 if max_distance is None else check.integer(
        "max_distance", max_distance, low=0, high=min(ind.shape) // 2)
    size = ind.shape if periodic else tuple(2 * n for n in ind.shape)
    spec = np.fft.rfftn(ind, s=size, axes=(0, 1, 2))
    corr = np.fft.irfftn(spec * np.conj(spec), s=size, axes=(0, 1, 2))
    # signed offset of each FFT index; on the doubled grid, index n is offset +-n (no pairs)
    lags = [np.where(np.arange(m) <= m // 2, np.arange(m), np.arange(m) - m) for m in size]
    if periodic:
        corr /= ind.size
    else:
        pairs = np.ones(size)
        for axis, (n, lag) in enumerate(zip(ind.shape, lags)):
            pairs = pairs * np.maximum(n - np.abs(lag), 0).reshape([-1 if a == axis else 1 for a in range(3)])
        corr = np.divide(corr, pairs, out=np.zeros(size), where=pairs > 0)
    grids = np.meshgrid(*[np.abs(lag) for lag in lags], indexing="ij")
    dist = np.rint(np.sqrt(sum(g.astype(np.float64) ** 2 for g in grids))).astype(np.int64).ravel()
    keep = dist <= r_max
    sums = np.bincount(dist[keep], weights=corr.ravel()[keep], minlength=r_max + 1)
    counts = np.bincount(dist[keep], minlength=r_max + 1)
    return sums / np.maximum(counts, 1)


def specific_surface_area(volume, *, threshold="otsu", spacing: float = 1.0) -> float:
    """Interface area of the phase per unit volume (units: 1 / length), by marching cubes.

    A grey volume's surface is its iso-surface at the threshold (sub-voxel accurate); a bool
    volume's is the 0.5 iso-surface of the indicator (``skimage.measure.marching_cubes``). The
    surface is not closed at the volume's faces; its area is divided by ``N1 N2 N3 spacing^3``.
    A bool volume's voxel staircase reads about 9 % above the smooth surface it samples (a
    digital ball: +8.8 %; thresholded smooth noise: +8.6 % against the grey iso-surface); PoreSpy
    and TauFactor blur the indicator first (docs/materials.md).

    Examples
    --------
    >>> slab = np.zeros((10, 10, 10), dtype=bool); slab[:, :, :5] = True
    >>> round(specific_surface_area(slab), 6)    # one 9 x 9 plane inside a 1000-voxel cube
    0.081
    """
    a = np.asarray(volume)
    spacing = check.real("spacing", spacing, low=0.0, low_open=True)
    ind = phase(a, threshold=threshold)
    if ind.all() or not ind.any():
        return 0.0
    if a.dtype == bool:
        field, level = ind.astype(np.float32), 0.5
    else:
        field = (a.astype(np.float64).mean(axis=3) if a.ndim == 4 else a.astype(np.float64))
        level = otsu_threshold(field) if isinstance(threshold, str) else float(threshold)
    measure = _optional("skimage.measure", "specific_surface_area (marching cubes)")
    verts, faces, _, _ = measure.marching_cubes(field, level, spacing=(spacing,) * 3)
    return float(measure.mesh_surface_area(verts, faces) / (ind.size * spacing ** 3))


def chord_lengths(volume, axis: int, *, threshold="otsu", include_border: bool = False) -> np.ndarray:
    """Lengths (in voxels) of the runs of the phase along ``axis``.

    Runs that touch the volume's faces along ``axis`` are cut and left out unless
    ``include_border``.

    >>> chord_lengths(np.array([[[1, 1, 0, 1, 0, 0, 1]]], dtype=bool), 2, include_border=True).tolist()
    [2, 1, 1]
    """
    axis = check.integer("axis", axis, low=0, high=2)
    ind = np.moveaxis(phase(volume, threshold=threshold), axis, -1).reshape(-1, np.shape(volume)[axis])
    padded = np.zeros((ind.shape[0], ind.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = ind
    step = np.diff(padded, axis=1)
    _, starts = np.nonzero(step == 1)
    _, ends = np.nonzero(step == -1)  # row-major order: run k's start and end pair up
    lengths = ends - starts
    if not include_border:
        inside = (starts > 0) & (ends < ind.shape[1])
        lengths = lengths[inside]
    return lengths.astype(np.int64)


def chord_length_distribution(volume, axis: int, *, threshold="otsu", max_length: int | None = None,
                              include_border: bool = False) -> np.ndarray:
    """Probability of each chord length ``1 .. max_length`` along ``axis`` (index 0 = length 1);
    longer chords count in the last bin. Zeros when there is no chord."""
    lengths = chord_lengths(volume, axis, threshold=threshold, include_border=include_border)
    top = np.shape(volume)[axis] if max_length is None else check.integer("max_length", max_length, low=1)
    hist = np.bincount(np.minimum(lengths, top) - 1, minlength=top)[:top].astype(np.float64)
    return hist / hist.sum() if hist.sum() else hist


def tortuosity(volume, *, axis: int = 0, threshold="otsu") -> float:
    """Tortuosity factor of the phase for diffusion along ``axis``, by ``taufactor``.

    Needs the optional dependency ``taufactor`` (``pip install 'npmrf3d[materials]'``, which brings
    PyTorch); its ``Solver(img).solve()`` gives ``tau = phase fraction / relative effective
    diffusivity`` (1 = straight channels; larger = more tortuous), on the GPU when PyTorch sees
    one, else on the CPU.

    Raises
    ------
    ParameterError
        taufactor is not installed, or the phase does not percolate along ``axis``.
    """
    axis = check.integer("axis", axis, low=0, high=2)
    taufactor = _optional("taufactor", "tortuosity")
    ind = np.moveaxis(phase(volume, threshold=threshold), axis, 0).astype(np.float32)
    if not ind.any():
        check.fail("tortuosity: the phase is empty; choose another threshold")
    torch = _optional("torch", "tortuosity (taufactor's solver)")
    # taufactor defaults to CUDA and warns when falling back; ask for the CPU when there is no GPU
    solver = taufactor.Solver(ind, device="cuda" if torch.cuda.is_available() else "cpu")
    solver.solve(verbose="")
    tau = float(np.asarray(solver.tau).ravel()[0])
    if not np.isfinite(tau) or tau <= 0:
        check.fail(f"tortuosity: the phase does not percolate along axis {axis} (taufactor gave {tau})")
    return tau


def octant_fractions(volume, *, threshold="otsu") -> np.ndarray:
    """The share of the phase (:func:`phase`) in each of the volume's 8 octants, ``(2, 2, 2)``
    (an odd side leaves its middle plane to the upper half).

    >>> v = np.zeros((4, 4, 4)); v[:2, :2, :2] = 1
    >>> f = octant_fractions(v, threshold=0.5)
    >>> float(f[0, 0, 0]), float(f.sum())
    (1.0, 1.0)
    """
    ind = phase(volume, threshold=threshold)
    half = [n // 2 for n in ind.shape]
    out = np.empty((2, 2, 2))
    for octant in np.ndindex(2, 2, 2):
        box = tuple(slice(0, h) if o == 0 else slice(h, None) for o, h in zip(octant, half))
        out[octant] = ind[box].mean()
    return out


def stationarity_warning(volume) -> str | None:
    """A one-line warning when a 3D exemplar is far from stationary, else None: when the share of
    its phase above Otsu's threshold differs between two octants by more than
    :data:`OCTANT_SPREAD`. ``volume-lh`` and ``npmrf-3d`` copy neighbourhoods as if every part of
    the exemplar were alike; a phase that lies in one region only (the outside of a head, a
    scan's edge) is then lost (``docs/volume.md``)."""
    fractions = octant_fractions(volume)
    low, high = float(fractions.min()), float(fractions.max())
    if high - low <= OCTANT_SPREAD:
        return None
    return (f"the exemplar is not stationary: the share of voxels above its Otsu threshold is "
            f"{low:.2f} in one octant and {high:.2f} in another; a phase that lies in one region "
            f"may be lost, so crop the scan to a region that looks alike throughout")


def structure_summary(volume, *, threshold="otsu", max_distance: int = 16,
                      spacing: float = 1.0) -> dict:
    """The statistics above in one JSON-able dict (no tortuosity): ``fraction``,
    ``two_point`` (per axis, periodic), ``two_point_radial``, ``surface_area`` (specific surface
    area) and ``mean_chord`` per axis (phase runs inside the volume)."""
    ind = phase(volume, threshold=threshold)
    r = min(max_distance, min(ind.shape) // 2)
    s2 = two_point_correlation(ind, True, max_distance=r, periodic=True)
    chords = [chord_lengths(ind, a) for a in range(3)]
    return {
        "fraction": float(ind.mean()),
        "two_point": s2.tolist(),
        "two_point_radial": radial_two_point(ind, max_distance=r).tolist(),
        "surface_area": specific_surface_area(ind, spacing=spacing),
        "mean_chord": [float(c.mean()) if len(c) else 0.0 for c in chords],
    }


def _face_labels(ind: np.ndarray) -> np.ndarray:
    """Connected components of an indicator (any ndim), face neighbours only."""
    return ndimage.label(ind, structure=ndimage.generate_binary_structure(ind.ndim, 1))[0]


def _spanning(labels: np.ndarray, axis: int) -> np.ndarray:
    """The component labels present on both faces normal to ``axis``."""
    first = np.take(labels, 0, axis=axis)
    last = np.take(labels, -1, axis=axis)
    return np.intersect1d(first[first > 0], last[last > 0])


def percolates(volume, *, threshold="otsu") -> list[bool]:
    """Whether the phase (:func:`phase`; an image or a volume of any ndim given as a bool
    indicator) connects the two faces normal to each axis, through face neighbours
    (``scipy.ndimage.label`` with face connectivity: 6 neighbours in 3D, 4 in 2D).

    >>> tube = np.zeros((4, 4, 4), dtype=bool); tube[:, 1, 1] = True
    >>> percolates(tube)
    [True, False, False]
    """
    a = np.asarray(volume)
    ind = a if a.dtype == bool else phase(a, threshold=threshold)
    labels = _face_labels(ind)
    return [bool(_spanning(labels, axis).size) for axis in range(ind.ndim)]


#: The solvers :func:`relative_diffusivity` offers.
DIFFUSIVITY_SOLVERS = ("finite-volume", "taufactor")


def relative_diffusivity(volume, *, axis: int = 0, threshold="otsu", solver: str = "finite-volume",
                         rtol: float = 1e-8) -> float:
    """Relative effective diffusivity ``D_eff / D`` of the phase along ``axis``: 0 when the phase
    does not connect the two faces normal to ``axis``, 1 for a volume all phase, the phase's
    fraction for straight channels along ``axis``; ``fraction / tortuosity factor``.

    ``finite-volume``: steady diffusion through the phase voxels (conductance 1 between face
    neighbours), concentration fixed at 1 and 0 on the outer faces of the first and last layers
    along ``axis`` (half a voxel from their centres: conductance 2), no flux through the other
    faces -- TauFactor's problem (Cooper et al. 2016). Only the components that touch both ends
    carry flux; the others are dropped before the solve. The sparse system is solved by conjugate
    gradients with a diagonal preconditioner to ``rtol``, BLAS on one thread (about 4 s for
    10^5 unknowns). ``D = flux * length / cross-section``. ``taufactor``: :func:`tortuosity`
    (the ``[materials]`` extra), ``fraction / tau``.

    >>> zigzag = np.zeros((4, 3, 3), dtype=bool); zigzag[:2, 1, 0] = zigzag[1:, 1, 1] = True
    >>> round(relative_diffusivity(zigzag) * 9 * 5 / 4, 9)   # 5 voxels in series over length 4
    1.0
    """
    axis = check.integer("axis", axis, low=0, high=2)
    check.choice("solver", solver, DIFFUSIVITY_SOLVERS)
    a = np.asarray(volume)
    ind = phase(a, threshold=threshold)
    if not ind.any():
        return 0.0
    if solver == "taufactor":
        if not percolates(ind)[axis]:
            return 0.0
        return float(ind.mean() / tortuosity(ind, axis=axis))
    ind = np.moveaxis(ind, axis, 0)
    labels = _face_labels(ind)
    keep = np.isin(labels, _spanning(labels, 0))
    count = int(keep.sum())
    if not count:
        return 0.0
    index = np.full(ind.shape, -1, dtype=np.int64)
    index[keep] = np.arange(count)
    pairs = []
    for step in range(3):
        low = tuple(slice(0, -1) if a == step else slice(None) for a in range(3))
        high = tuple(slice(1, None) if a == step else slice(None) for a in range(3))
        both = keep[low] & keep[high]
        pairs.append((index[low][both], index[high][both]))
    i = np.concatenate([p[0] for p in pairs])
    j = np.concatenate([p[1] for p in pairs])
    inlet, outlet = index[0][keep[0]], index[-1][keep[-1]]
    diagonal = np.bincount(np.concatenate([i, j]), minlength=count).astype(np.float64)
    np.add.at(diagonal, inlet, 2.0)
    np.add.at(diagonal, outlet, 2.0)
    rhs = np.zeros(count)
    np.add.at(rhs, inlet, 2.0)
    ones = -np.ones(2 * i.size)
    matrix = sparse.csr_matrix((np.concatenate([ones, diagonal]),
                                (np.concatenate([i, j, np.arange(count)]),
                                 np.concatenate([j, i, np.arange(count)]))), shape=(count, count))
    start = 1.0 - (np.nonzero(keep)[0] + 0.5) / ind.shape[0]   # the straight-channel profile
    with threadpool_limits(limits=1, user_api="blas"):  # BLAS threads only slow these small products
        conc, info = linalg.cg(matrix, rhs, x0=start, rtol=rtol, maxiter=100 * count,
                               M=sparse.diags(1.0 / diagonal))
    if info != 0:
        check.fail(f"relative_diffusivity: the solve did not converge along axis {axis}")
    flux = float(np.sum(2.0 * (1.0 - conc[inlet])))
    return flux * ind.shape[0] / (ind.shape[1] * ind.shape[2])


def interface_density(volume, axis: int, *, threshold="otsu") -> float:
    """Phase boundaries crossed per unit length along ``axis`` (``P_L``): the share of
    neighbouring pairs along ``axis`` with one voxel in the phase and the other not. Works on an
    image or a volume of any ndim given as a bool indicator. For an isotropic structure the
    specific surface area is ``2 P_L`` along any axis (stereology: Underwood 1970), so a slice's
    ``2 P_L`` along its axes and a volume's along the same directions compare like with like.

    >>> interface_density(np.array([[1, 1, 0, 0, 1]], dtype=bool), 1)
    0.5
    """
    a = np.asarray(volume)
    ind = a if a.dtype == bool else phase(a, threshold=threshold)
    axis = check.integer("axis", axis, low=0, high=ind.ndim - 1)
    if ind.shape[axis] < 2:
        return 0.0
    return float(np.diff(ind.astype(np.int8), axis=axis).astype(bool).mean())
