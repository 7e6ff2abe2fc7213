"""Views, windows and the interaction colouring (docs/model.md, sections 1 and 6)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from npmrf3d.model import neighbourhood as nb
from tests import naive

VIEWS3 = ("front", "right", "top")
SUBSETS = [s for n in (1, 2, 3) for s in itertools.combinations(VIEWS3, n)]


@pytest.mark.parametrize("window", [3, 5, 7, 9, 15])
def test_window_offsets(window):
    off = nb.window_offsets(window)
    r = window // 2
    assert off.shape == (window**2 - 1, 2) and off.dtype == np.int64
    assert not ((off[:, 0] == 0) & (off[:, 1] == 0)).any()
    assert len({tuple(o) for o in off}) == window**2 - 1
    assert np.abs(off).max() == r
    assert off.tolist() == [list(o) for o in naive.naive_window_offsets(window)]  # row-major


@pytest.mark.parametrize("window", [3, 5, 9])
def test_view_axis_mapping(window):
    """front varies axes (0, 1), right (1, 2), top (0, 2); exemplar row first, column second."""
    varying = {"front": (0, 1), "right": (1, 2), "top": (0, 2)}
    plane = nb.window_offsets(window)
    for view, (row_axis, col_axis) in varying.items():
        off = nb.view_offsets(view, window)
        assert off.shape == (window**2 - 1, 3) and off.dtype == np.int64
        fixed = 3 - row_axis - col_axis
        assert (off[:, fixed] == 0).all()
        np.testing.assert_array_equal(off[:, row_axis], plane[:, 0])
        np.testing.assert_array_equal(off[:, col_axis], plane[:, 1])
        np.testing.assert_array_equal(off, naive.naive_view_offsets(view, window))
        assert nb.VIEW_AXES[view] == (row_axis, col_axis)
    assert nb.VIEWS == VIEWS3


def test_slices_match_the_documented_orientation():
    """volume[:, :, k] is a front slice, volume[i] a right slice, volume[:, j] a top slice,
    each with the exemplar's orientation: offset (d_row, d_col) moves along (row, col)."""
    volume = np.arange(5 * 6 * 7).reshape(5, 6, 7)
    i, j, k = 2, 3, 4
    for view, sl, centre in (("front", volume[:, :, k], (i, j)), ("right", volume[i], (j, k)),
                             ("top", volume[:, j], (i, k))):
        for (dr, dc), o in zip(nb.window_offsets(3), nb.view_offsets(view, 3)):
            assert volume[i + o[0], j + o[1], k + o[2]] == sl[centre[0] + dr, centre[1] + dc]


@pytest.mark.parametrize("window", [3, 5, 9])
@pytest.mark.parametrize("views", SUBSETS)
def test_union_offsets(window, views):
    union = nb.union_offsets(views, window)
    assert union.dtype == np.int64
    as_set = {tuple(int(x) for x in o) for o in union}
    assert len(as_set) == len(union)  # distinct
    assert as_set == naive.naive_union_offsets(views, window)
    m = window**2 - 1
    # each pair of views shares the w - 1 offsets along their common axis
    expected = {1: m, 2: 2 * m - (window - 1), 3: 3 * m - 3 * (window - 1)}[len(views)]
    assert len(union) == expected
    assert (0, 0, 0) not in as_set


def test_union_size_three_views_examples():
    assert len(nb.union_offsets(VIEWS3, 3)) == 18
    assert len(nb.union_offsets(VIEWS3, 7)) == 3 * 48 - 3 * 6
    assert len(nb.union_offsets(VIEWS3, 9)) == 216


# --------------------------------------------------------------------------- colouring


def class_index(classes, shape) -> np.ndarray:
    """Class number of every site; -1 if missing. Asserts no site is listed twice."""
    code = np.full(shape, -1, dtype=np.int64)
    count = np.zeros(shape, dtype=np.int64)
    for c, sites in enumerate(classes):
        assert sites.ndim == 2 and sites.shape[1] == 3 and sites.dtype == np.int64
        np.add.at(count, tuple(sites.T), 1)
        code[tuple(sites.T)] = c
    assert (count == 1).all(), "every site must be in exactly one class"
    return code


def conflicting_pairs(code, views, window) -> int:
    """Number of (site, offset in N_s) pairs whose two sites share a class, on the torus.

    Exactly the brute-force pair check: b interacts with a iff b - a = o (mod shape) for an
    offset o of the union of the views' windows (naive.naive_union_offsets).
    """
    bad = 0
    for o in naive.naive_union_offsets(views, window):
        bad += int((code == np.roll(code, shift=o, axis=(0, 1, 2))).sum())
    return bad


@pytest.mark.parametrize(("shape", "window"), [((8, 8, 8), 3), ((10, 9, 7), 5), ((4, 5, 6), 3),
                                               ((3, 3, 3), 5)])
def test_colour_classes_brute_force(shape, window):
    classes = nb.colour_classes(shape, window)
    class_index(classes, shape)
    assert naive.naive_colouring_ok(classes, shape, VIEWS3, window)


def test_colour_classes_w9_on_64_cube():
    """docs/model.md, section 6: r + 1 = 5 does not divide 64, so the wrapping blocks need care."""
    shape, window = (64, 64, 64), 9
    classes = nb.colour_classes(shape, window)
    code = class_index(classes, shape)
    assert conflicting_pairs(code, VIEWS3, window) == 0
    # and a few classes pair by pair (vectorised torus differences), wrapping ones included
    n = np.array(shape)
    r = window // 2
    # the classes of a regular site, of sites in the leftover (wrapping) band of one or two
    # axes, and of the corner
    picks = [code[0, 0, 0], code[60, 0, 0], code[1, 61, 3], code[2, 62, 63], code[63, 63, 63]]
    assert [len(classes[c]) for c in picks] == [12**3, 12**2, 12**2, 12, 1]
    for c in picks:
        s = classes[c]
        d = (s[:, None, :] - s[None, :, :]) % n
        d = np.minimum(d, n - d)  # torus distance per axis
        same = d == 0
        near = d <= r
        off_diag = ~np.eye(len(s), dtype=bool)
        for a, b in ((0, 1), (1, 2), (0, 2)):  # the three view planes
            normal = 3 - a - b
            hit = same[..., normal] & near[..., a] & near[..., b] & off_diag
            assert not hit.any()


def test_conflict_check_catches_the_plain_modulo_colouring():
    """The checker has teeth: plain (i, j, k) mod (r + 1) colours clash across the wrap of 64."""
    shape, window = (64, 64, 64), 9
    p = window // 2 + 1
    i, j, k = np.indices(shape)
    code = (i % p) * p * p + (j % p) * p + (k % p)
    assert conflicting_pairs(code, VIEWS3, window) > 0
    # a tiny case through the brute-force twin as well
    shape = (5, 4, 4)
    i, j, k = np.indices(shape)
    code = (i % 2) * 4 + (j % 2) * 2 + (k % 2)
    classes = [np.argwhere(code == c).astype(np.int64) for c in range(8)]
    assert not naive.naive_colouring_ok(classes, shape, VIEWS3, 3)


@pytest.mark.parametrize(("n", "period"), [(8, 2), (9, 3), (10, 3), (64, 5), (4, 5), (7, 7)])
def test_axis_colours_separation(n, period):
    colours = nb.axis_colours(n, period)
    assert colours.shape == (n,)
    for a in range(n):
        for b in range(a + 1, n):
            if colours[a] == colours[b]:
                d = b - a
                assert min(d, n - d) >= period


def test_colour_classes_are_deterministic_and_cover_small_shapes():
    a = nb.colour_classes((6, 7, 8), 5)
    b = nb.colour_classes((6, 7, 8), 5)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert sum(len(c) for c in a) == 6 * 7 * 8
