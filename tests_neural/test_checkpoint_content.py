"""Training checkpoints whose checksum holds but whose contents are not a state of this run:
one member changed and the file re-sealed (:func:`tests.test_checkpoint_content.craft`, with
:func:`npmrf3d.io.checkpoints.seal`) is refused with the one checkpoint refusal."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch

from npmrf3d.errors import ParameterError
from npmrf3d.io.checkpoints import as_bytes_array
from npmrf3d.methods import neural
from tests.test_checkpoint_content import REFUSED, _apply, _drop, _json, _set, craft


def _torch_bytes(fn):
    def change(members):
        state = torch.load(io.BytesIO(members["torch_state"].tobytes()), weights_only=True)
        buffer = io.BytesIO()
        torch.save(fn(state), buffer)
        members["torch_state"] = as_bytes_array(buffer.getvalue())
    return change


def _shrink_first_weight(state):
    name = next(iter(state["generator"]))
    state["generator"][name] = state["generator"][name][..., :1]
    return state


CASES = {
    "iteration -1": (_set("iteration", -1), "'iteration' is -1"),
    "iteration beyond the losses": (_set("iteration", 99), "'history' has shape (3,)"),
    "iteration as text": (_set("iteration", "3"), "'iteration' is '3'"),
    "history with NaN": (_apply("history", lambda h: np.full_like(h, np.nan)), "'history' holds NaN"),
    "seconds negative": (_set("seconds", -1.0), "'seconds' is -1.0"),
    "rng_state garbage": (_set("rng_state", "garbage{"), "'rng_state'"),
    "rng_state of another generator": (
        _json("rng_state", lambda s: {**s, "bit_generator": "MT19937"}), "'MT19937'"),
    "torch_state garbage": (_set("torch_state", np.frombuffer(b"garbage", np.uint8)), "'torch_state' cannot be read"),
    "torch_state as floats": (_apply("torch_state", lambda b: b.astype(np.float32)), "'torch_state' is not the bytes"),
    "torch_state without the optimizer": (_torch_bytes(lambda s: {"generator": s["generator"]}),
                                          "no generator and optimizer"),
    "torch_state of another shape": (_torch_bytes(_shrink_first_weight), "does not fit this generator"),
    "history missing": (_drop("history"), "member 'history' is missing"),
    "extra member": (_set("bogus", 1), "member 'bogus' is not part"),
}


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from tests_neural.conftest import TINY

    path = tmp_path_factory.mktemp("neural") / "train.ckpt"
    rng = np.random.default_rng(0)
    exemplar = rng.random((24, 24)).astype(np.float32)
    neural.train(exemplar, rng=1, checkpoint=path, **TINY)
    return path, exemplar


def test_unchanged_checkpoint_resealed_resumes(finished, tmp_path):
    from tests_neural.conftest import TINY

    source, exemplar = finished
    path = craft(source, tmp_path / "c.ckpt", lambda members: None)
    assert len(neural.train(exemplar, rng=1, checkpoint=path, **TINY).history) == TINY["iterations"]


@pytest.mark.parametrize("case", sorted(CASES))
def test_changed_member_is_refused(case, finished, tmp_path):
    from tests_neural.conftest import TINY

    source, exemplar = finished
    change, words = CASES[case]
    path = craft(source, tmp_path / "c.ckpt", change)
    before = path.read_bytes()
    with pytest.raises(ParameterError) as caught:
        neural.train(exemplar, rng=1, checkpoint=path, **TINY)
    message = str(caught.value)
    assert REFUSED in message and words in message, message
    assert "\n" not in message
    assert path.read_bytes() == before
