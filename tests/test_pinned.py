"""Pinned volumes: small runs of every method must stay bit-identical across refactoring.

These hashes are *not* expected results in the scientific sense (nothing here says the volumes
are good); they were computed from the code of a reviewed state and pin its behaviour, so that moving the level loop, the
relaxations, the up-sampling and the method registry around cannot silently change any volume
for a given seed and configuration. A deliberate change of an algorithm's output updates the
hash in the same commit and says why in the message.

The hashes are sha256 of the volume's float32 bytes (C order). They hold on one platform and
numba/numpy version; a different CPU's libm could change the last bit of an ``exp``, in which
case re-pin on that machine from the commit named above.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import npmrf3d
from npmrf3d import data
from npmrf3d.methods.chen_wang import chen_wang_synthesize
from tests.conftest import checkerboard as checker


def _ihc():
    return data.path("ihc64")


PINNED = {
    "npmrf_icm_default": (
        lambda: npmrf3d.synthesize(checker(), size=16, window=5, levels=2, variant="sharp", rng=7),
        "d8188583ec25a2002eefc7b6788956cca79a1e5f2bc00d77cfafbe63f7876807"),
    "npmrf_icm_literal": (
        lambda: npmrf3d.synthesize(checker(), size=16, window=5, levels=2, variant="literal", rng=7),
        "95ce180fe6640b9fc1e2c6a737c7676e7dccec1546a333122c6b42dc5a78dd3e"),
    "npmrf_icm_8of8_fixed": (
        lambda: npmrf3d.synthesize(checker(), size=16, window=3, levels=2, upsample="8/8",
                                   inherit="fixed", views="front,right", variant="sharp", rng=5),
        "95fb8f536f248435bf22829e9a7d5645c7fd1571e81cc6f523d6c8063351dd6e"),
    "npmrf_anneal_heatbath": (
        lambda: npmrf3d.synthesize(_ihc(), size=8, window=3, levels=2, relaxation="anneal",
                                   support="full", palette=8, proposals=2, rng=7),
        "2c7246a546b49389d73f481e20477dab577cdbe55f20d308a886e532842a0934"),
    "npmrf_anneal_metropolis": (
        lambda: npmrf3d.synthesize(_ihc(), size=8, window=3, levels=2, relaxation="anneal",
                                   support="full", sampler="metropolis", palette=8, proposals=2, rng=7),
        "e1004b2c16282c4594730026e7c923b506d69e0645c8c6b024449f0779e55d0b"),
    "kopf_trilinear": (
        lambda: npmrf3d.kopf_synthesize(_ihc(), size=16, window=4, levels=2, iterations=2, rng=7),
        "e005262b17adbd0a68876264095345f327d57163dc5a1d08c0fa930e62881ce7"),
    "kopf_8of8_plain": (
        lambda: npmrf3d.kopf_synthesize(checker(), size=16, window=4, levels=2, iterations=(1, 2),
                                        upsample="8/8", mean_shift=None, rng=3),
        "2e9a1b64847bc1b2530c8fc4fb599c36e8d970a834f9fd5e3daf79e64f471070"),
    "kopf_1of8": (
        lambda: npmrf3d.kopf_synthesize(checker(), size=8, window=4, levels=2, iterations=1,
                                        upsample="1/8", views="front,top", rng=3),
        "4dc32e57b84bd363472d19c27b3792113f8b29f5230079ca5669747e7f93f7f4"),
    # the coherent support and Chen-Wang (k-coherence sets, exclusion, global k-d tree matches),
    # pinned from the code as it stood before the level models' nearest-neighbour search kept
    # repeated patches once (npmrf3d.model.nearest): these exemplars repeat too few patches for
    # that path, so their volumes must not move
    "coherent_ihc64": (
        lambda: npmrf3d.synthesize(_ihc(), size=16, levels=2, phase_weight=0.0, grid=1, rng=7),
        "8b75adb0bd7193ef09e4032e748f4a07a98e2ef3d0691d8333593aa46847df9e"),
    "coherent_gravel64_grey": (
        lambda: npmrf3d.synthesize(data.path("gravel64"), size=16, levels=2, window=5, phase_weight=0.0,
                                   grid=1, rng=3),
        "f93e66edc88cfc2ea4413cec91ff1d2a5002d901dd120fc14a9627e1c04de196"),
    # with every site searched and voting (grid 1)
    "coherent_ihc64_phase": (
        lambda: npmrf3d.synthesize(_ihc(), size=16, levels=2, grid=1, rng=7),
        "66b501bb096b4f53d6644fac4f3a7b62092a2e4cf0777bdcddbfd572684c8b7e"),
    "coherent_gravel64_grey_phase": (
        lambda: npmrf3d.synthesize(data.path("gravel64"), size=16, levels=2, window=5, grid=1, rng=3),
        "9f7830ade79b98c159ecdd105122dd5830e4b19d425497bb4dbc93de013639ca"),
    "coherent_checker": (
        lambda: npmrf3d.synthesize(checker(), size=16, levels=2, window=5, grid=1, rng=7),
        "60f60dee26b389fc239b76813e1c92010e9b126b0cbd91f1f86148c8551df2c1"),
    # the default: its phase control, sites every 2nd voxel
    "coherent_ihc64_default": (
        lambda: npmrf3d.synthesize(_ihc(), size=16, levels=2, rng=7),
        "76c56e6bb0b79fd279c72042cca5cf0acf6e4fca63205d05c7288831c5118092"),
    "coherent_gravel64_grey_default": (
        lambda: npmrf3d.synthesize(data.path("gravel64"), size=16, levels=2, window=5, rng=3),
        "bfc5554848f0b13fdb8f24c3715f91ee6868d02363356c06b850ec7bfcae4f10"),
    "chen_wang_global_exclude": (
        lambda: chen_wang_synthesize(_ihc(), size=16, window=(6, 4), levels=2, iterations=(2, 2),
                                     global_share=0.2, coherence_exclude=2.0, rng=5),
        "dd1d3235189fc9fc2e269443c0acf2cdac9c004e46bfd134ce7dfc56114bda6c"),
}


def volume_hash(volume: np.ndarray) -> str:
    """sha256 of the float32 bytes of ``volume`` in C order."""
    return hashlib.sha256(np.ascontiguousarray(volume, dtype=np.float32).tobytes()).hexdigest()


@pytest.mark.parametrize("name", sorted(PINNED))
def test_pinned_volume_is_bit_identical(name):
    make, expected = PINNED[name]
    assert volume_hash(make().volume) == expected
