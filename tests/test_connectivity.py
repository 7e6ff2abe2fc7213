"""The minority phase's detached pieces (npmrf3d/model/connectivity.py)."""

from __future__ import annotations

import numpy as np

from npmrf3d.model.connectivity import attached_view, minority_below


def test_pieces_apart_from_the_largest_take_the_majority_colour():
    v = np.ones((8, 8, 8, 1), dtype=np.float32)          # majority: 1 (grain); the phase: 0 (pore)
    v[:, 2, 2] = 0.0                                       # a tube along axis 0, 8 voxels
    v[3, 5, 5] = v[3, 5, 6] = 0.0                          # a detached piece of 2
    v[1, 0, 7] = 0.125                                     # a piece of 1, a coarse level's grey value
    lo, span = np.zeros(1), np.ones(1)
    assert minority_below([v[0]], lo, span)
    out = attached_view(v, lo, span, below=True)
    assert out.dtype == v.dtype and out.shape == v.shape
    np.testing.assert_array_equal(out[:, 2, 2, 0], 0.0)
    assert out[3, 5, 5, 0] == out[3, 5, 6, 0] == out[1, 0, 7, 0] == 1.0
    assert (out != v).sum() == 3
    assert v[3, 5, 5, 0] == 0.0                            # the input is left as it was


def test_pieces_joined_across_the_faces_are_one():
    v = np.zeros((8, 8, 8, 1), dtype=np.float32)         # majority 0; the phase: 1
    v[0:2, 4, 4] = v[6:8, 4, 4] = 1.0                     # one piece of 4 through the faces of axis 0
    v[3, 1, 1:4] = 1.0                                     # a straight piece of 3
    out = attached_view(v, np.zeros(1), np.ones(1), below=False)
    assert out[[0, 1, 6, 7], 4, 4, 0].tolist() == [1.0] * 4
    assert out[3, 1, 1:4, 0].tolist() == [0.0] * 3


def test_one_piece_or_none_is_left_as_it_is():
    v = np.ones((4, 4, 4, 1), dtype=np.float32)
    assert attached_view(v, np.zeros(1), np.ones(1), below=True) is v
    v[1, 1, 1] = 0.0
    assert attached_view(v, np.zeros(1), np.ones(1), below=True) is v
