"""The materials statistics against PoreSpy (Gostick et al. 2019), the reference materials users
trust: each test converts one definition to the other's and asserts agreement within a stated
tolerance, and most also show that the unconverted definitions differ by more than it.

The definitions and the differences are in docs/materials.md.
"""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import porespy as ps
import pytest
from skimage import measure

from npmrf3d import data
from npmrf3d.analysis import materials
from npmrf3d.analysis.metrics import two_point_correlation

# porespy.metrics.chord_counts reads RegionProperties.filled_area, deprecated in scikit-image 0.26
CHORD_COUNTS_WARNING = "ignore:.RegionProperties.filled_area. is deprecated:FutureWarning"


@pytest.fixture(scope="module")
def blobs() -> np.ndarray:
    """PoreSpy's periodic blobs, 36 x 40 x 44 (sides differ: an axis mix-up shows), 40 % phase."""
    return ps.generators.blobs([36, 40, 44], porosity=0.4, blobiness=1, seed=3)


@pytest.fixture(scope="module")
def spheres() -> np.ndarray:
    """PoreSpy's overlapping spheres (radius 5) in a 40^3 box, not periodic, 60 % phase."""
    return ps.generators.overlapping_spheres([40, 40, 40], r=5, porosity=0.6, seed=5)


@pytest.fixture(scope="module")
def gravel() -> np.ndarray:
    """The bundled 128 x 128 grey gravel photograph as a one-slice volume ``(1, 128, 128)``."""
    return iio.imread(data.path("gravel"))[None].astype(np.float64)


@pytest.fixture
def stripes() -> np.ndarray:
    """Hand-made 8^3: the phase is the planes x = 0, 1, 4, 5 (axis 2)."""
    v = np.zeros((8, 8, 8), dtype=bool)
    v[:, :, [0, 1, 4, 5]] = True
    return v


def _radial_bins(r_max: int) -> np.ndarray:
    """PoreSpy's bin ``i`` is ``[edge_i, edge_i+1)``; ours collects ``round(|d|) = r``."""
    return np.arange(r_max + 2) - 0.5


def test_volume_fraction_is_porespys_porosity_of_the_same_phase(blobs, spheres, gravel):
    for ind in (blobs, spheres):
        assert materials.volume_fraction(ind) == ps.metrics.porosity(ind)
    # a grey volume: ours thresholds at Otsu's; PoreSpy counts the voxels equal to 1
    assert materials.volume_fraction(gravel) == ps.metrics.porosity(materials.phase(gravel))
    assert materials.volume_fraction(gravel) != pytest.approx(ps.metrics.porosity(gravel > gravel.mean()),
                                                              abs=1e-3)
    # PoreSpy ignores values other than 0 and 1 (a mask); ours would count a 2 as phase
    masked = spheres.astype(np.uint8)
    masked[:4] = 2
    assert ps.metrics.porosity(masked) == pytest.approx(spheres[4:].mean(), abs=1e-15)


@pytest.mark.parametrize("which", ["blobs", "spheres"])
def test_radial_two_point_without_wrapping_is_porespys(request, which):
    ind = request.getfixturevalue(which)
    r_max = min(ind.shape) // 2
    theirs = ps.metrics.two_point_correlation(ind, bins=_radial_bins(r_max))
    ours = materials.radial_two_point(ind, max_distance=r_max, periodic=False)
    np.testing.assert_allclose(ours, theirs.probability_scaled, rtol=0, atol=1e-12)
    # PoreSpy's .probability is S2 / S2(0), 1 at r = 0
    np.testing.assert_allclose(ours / ours[0], theirs.probability, rtol=0, atol=1e-12)
    # ours by default wraps around: close on PoreSpy's periodic blobs, not on the spheres
    gap = np.abs(materials.radial_two_point(ind, max_distance=r_max) - theirs.probability_scaled).max()
    assert gap < 0.005 if which == "blobs" else gap > 0.02


def test_radial_two_point_differs_from_porespys_with_its_default_bins(blobs):
    """PoreSpy's default ``bins=100`` spans ``[0, min(shape) // 2]`` in unit bins ``[k, k + 1)``;
    S2 falls steeply near 0, so its first bins are not ours."""
    ours = materials.radial_two_point(blobs, periodic=False)
    theirs = ps.metrics.two_point_correlation(blobs).probability_scaled
    assert abs(ours[1] - theirs[1]) > 0.01
    np.testing.assert_allclose(ours[-3:], theirs[-3:], atol=0.01)  # flat tail: bins hardly matter


@pytest.mark.parametrize("which, distances", [("blobs", (1, 2, 4)), ("gravel", (1, 2, 3, 4))])
def test_two_point_along_the_axes_is_porespys_at_axis_only_distances(request, which, distances):
    """A PoreSpy bin that holds only the distance ``r`` exactly is the mean over the axes of our
    non-periodic S2 along each axis wherever no other lattice offset has length ``r`` (3D:
    r = 1, 2, 4; 2D: r = 1 .. 4)."""
    vol = request.getfixturevalue(which)
    ind = materials.phase(vol)[0] if which == "gravel" else vol
    r_max = max(distances)
    edges = np.sort(np.concatenate([[0.0, 1e-6], np.arange(1, r_max + 1) - 1e-6,
                                    np.arange(1, r_max + 1) + 1e-6]))
    theirs = ps.metrics.two_point_correlation(ind, bins=edges).probability_scaled[::2]
    along = two_point_correlation(ind, True, max_distance=r_max)
    for r in (0, *distances):
        assert along[:, r].mean() == pytest.approx(theirs[r], abs=1e-12)
    wrapped = two_point_correlation(ind, True, max_distance=r_max, periodic=True).mean(axis=0)
    assert np.abs(wrapped[1:] - along.mean(axis=0)[1:]).max() > 1e-4


def test_hand_made_two_point_values(stripes):
    # along axis 2 inside the volume: r = 1 pairs (0,1), (4,5) of 7; r = 3 the pair (1,4) of 5
    expected_axis2 = [0.5, 2 / 7, 0.0, 1 / 5]
    along = two_point_correlation(stripes, True, max_distance=3)
    np.testing.assert_allclose(along, [[0.5] * 4, [0.5] * 4, expected_axis2], atol=1e-15)
    theirs = ps.metrics.two_point_correlation(stripes, bins=np.array([0, 1e-6, 1 - 1e-6, 1 + 1e-6]))
    assert theirs.probability_scaled[2] == pytest.approx((0.5 + 0.5 + 2 / 7) / 3, abs=1e-12)


def _porespy_lines(ind: np.ndarray, axis: int) -> np.ndarray:
    """The lines ``apply_chords(spacing=1, trim_edges=True)`` keeps: every other line, not the
    first and last sampled ones (its border clearing removes their chords)."""
    every_other = tuple(slice(None) if a == axis else slice(None, None, 2) for a in range(ind.ndim))
    inner = tuple(slice(None) if a == axis else slice(1, -1) for a in range(ind.ndim))
    return ind[every_other][inner]


@pytest.mark.filterwarnings(CHORD_COUNTS_WARNING)
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_chord_lengths_are_porespys_on_its_lines(blobs, axis):
    theirs = np.sort(ps.metrics.chord_counts(ps.filters.apply_chords(blobs, axis=axis)))
    ours = np.sort(materials.chord_lengths(_porespy_lines(blobs, axis), axis))
    np.testing.assert_array_equal(ours, theirs)
    every_other = tuple(slice(None) if a == axis else slice(None, None, 2) for a in range(3))
    kept = np.sort(ps.metrics.chord_counts(ps.filters.apply_chords(blobs, axis=axis, trim_edges=False)))
    np.testing.assert_array_equal(np.sort(materials.chord_lengths(blobs[every_other], axis,
                                                                  include_border=True)), kept)
    assert len(materials.chord_lengths(_porespy_lines(blobs, axis), axis, include_border=True)) > len(theirs)
    # all lines (ours) against PoreSpy's quarter of them: the same mean chord within 5 %
    assert materials.chord_lengths(blobs, axis).mean() == pytest.approx(theirs.mean(), rel=0.05)


@pytest.mark.filterwarnings(CHORD_COUNTS_WARNING)
def test_chord_length_distribution_is_porespys_histogram(spheres):
    chords = ps.filters.apply_chords(spheres, axis=1)
    ours = materials.chord_length_distribution(_porespy_lines(spheres, 1), 1)
    by_count = ps.metrics.chord_length_distribution(chords, bins=None)  # unit bins [L, L + 1)
    n = len(by_count.pdf) - 1
    np.testing.assert_allclose(by_count.pdf[0], 0.0)
    np.testing.assert_allclose(by_count.pdf[1:], ours[:n], rtol=0, atol=1e-12)
    assert ours[n:].sum() == 0.0
    # normalization="length" weights a chord by its bin's centre, L + 1/2, and divides by the sum
    # of the bins' weights each truncated to an integer (so its pdf sums to a little over 1)
    by_length = ps.metrics.chord_length_distribution(chords, bins=None, normalization="length")
    counts = np.bincount(materials.chord_lengths(_porespy_lines(spheres, 1), 1))[1:]
    weighted = counts * (np.arange(1, n + 1) + 0.5)
    np.testing.assert_allclose(by_length.pdf[1:], weighted / np.floor(weighted).sum(), rtol=0, atol=1e-12)
    assert by_length.pdf.sum() > 1.0
    assert np.abs(by_length.pdf[1:] - ours[:n]).max() > 0.05


@pytest.mark.filterwarnings(CHORD_COUNTS_WARNING)
def test_chords_of_the_bundled_gravel_and_of_a_hand_made_case(gravel, stripes):
    ind = materials.phase(gravel)
    for axis in (1, 2):
        theirs = np.sort(ps.metrics.chord_counts(ps.filters.apply_chords(ind[0], axis=axis - 1)))
        np.testing.assert_array_equal(np.sort(materials.chord_lengths(_porespy_lines(ind[0], axis - 1)[None], axis)),
                                      theirs)
    # runs 0-1 (cut by the face) and 4-5 on each of the 64 lines along axis 2; PoreSpy keeps the
    # 2 x 2 inner lines of its 4 x 4 sampled ones
    assert materials.chord_lengths(stripes, 2).tolist() == [2] * 64
    assert ps.metrics.chord_counts(ps.filters.apply_chords(stripes, axis=2)).tolist() == [2] * 4


def test_surface_area_is_porespys_mesh_area_once_closed_at_the_faces(spheres):
    ours = materials.specific_surface_area(spheres) * spheres.size
    verts, faces, _, _ = measure.marching_cubes(spheres.astype(np.float32), 0.5)
    assert ps.metrics.mesh_surface_area(verts=verts, faces=faces) == pytest.approx(ours, rel=1e-9)
    # PoreSpy meshes a region padded with empty voxels (closed at the volume's faces); with a
    # one-voxel element it does not blur, and the area is ours of the padded volume
    closed = ps.metrics.region_surface_areas(spheres.astype(np.int64), strel=np.ones((1, 1, 1)))[0]
    padded = np.pad(spheres, 1)
    assert closed == pytest.approx(materials.specific_surface_area(padded) * padded.size, rel=1e-6)
    # the caps on the faces are about the phase's area on them
    faces_area = sum(np.count_nonzero(np.take(spheres, i, axis=a)) for a in range(3) for i in (0, -1))
    assert closed - ours == pytest.approx(faces_area, rel=0.3)


@pytest.mark.parametrize("radius", [6.0, 12.0])
def test_surface_area_of_a_digital_ball_binary_and_blurred(radius):
    """The 0.5 iso-surface of a bool indicator overestimates a smooth surface (voxel staircase);
    PoreSpy blurs the indicator with a radius-1 ball first, which removes most of that."""
    z, y, x = np.mgrid[:36, :36, :36].astype(np.float64)
    ball = (z - 17.5) ** 2 + (y - 18.2) ** 2 + (x - 17.8) ** 2 <= radius ** 2
    exact = 4 * np.pi * radius ** 2
    ours = materials.specific_surface_area(ball) * ball.size
    blurred = ps.metrics.region_surface_areas(ball.astype(np.int64))[0]
    assert 1.07 < ours / exact < 1.10
    assert blurred == pytest.approx(exact, rel=0.02)
