"""Training: checkpoints resume bit for bit, the VGG-19 path, model files, validation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from npmrf3d.errors import ParameterError
from npmrf3d.methods import neural
from npmrf3d.methods.neural.descriptor import VGG19_CONVS


def _state(model):
    return {k: v.clone() for k, v in model.generator.state_dict().items()}


def test_resume_from_checkpoint_is_bit_identical(tmp_path, exemplar, tiny_options):
    options = {**tiny_options, "iterations": 4, "checkpoint_every": 1, "seed": 3}
    full = neural.train(exemplar, rng=1, **options)
    path = tmp_path / "train.ckpt"

    class Stop(Exception):
        pass

    def interrupt(step, steps, loss):
        if step == 2:
            raise Stop

    with pytest.raises(Stop):
        neural.train(exemplar, rng=1, checkpoint=path, progress=interrupt, **options)
    assert path.exists()
    resumed = neural.train(exemplar, rng=1, checkpoint=path, **options)
    assert resumed.history == full.history
    for name, value in _state(full).items():
        assert torch.equal(value, resumed.generator.state_dict()[name]), name
    np.testing.assert_array_equal(neural.generate(full, (0, 0, 0), 16), neural.generate(resumed, (0, 0, 0), 16))


def test_a_checkpoint_of_another_run_is_refused(tmp_path, exemplar, tiny_options):
    path = tmp_path / "train.ckpt"
    neural.train(exemplar, rng=1, checkpoint=path, **tiny_options)
    with pytest.raises(ParameterError, match="different configuration"):
        neural.train(exemplar, rng=1, checkpoint=path, **{**tiny_options, "batch": 2})
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(ParameterError, match="is not a checkpoint file of npmrf3d"):
        neural.train(exemplar, rng=1, checkpoint=path, **tiny_options)


def test_seeded_training_repeats(exemplar, tiny_options):
    a = neural.train(exemplar, rng=2, **tiny_options)
    b = neural.train(exemplar, rng=2, **tiny_options)
    assert a.history == b.history
    c = neural.train(exemplar, rng=4, **tiny_options)
    assert a.history != c.history


def test_loss_goes_down(exemplar, tiny_options):
    model = neural.train(exemplar, rng=0, **{**tiny_options, "iterations": 40})
    assert np.mean(model.history[-5:]) < 0.7 * np.mean(model.history[:3])


def test_three_views_with_their_own_rgb_exemplars(exemplar_rgb, tiny_options):
    other = exemplar_rgb[::-1].copy()
    model = neural.train(exemplar_rgb, exemplars={"top": other}, rng=0, **tiny_options)
    volume = neural.generate(model, (0, 0, 0), (8, 9, 10))
    assert volume.shape == (8, 9, 10, 3) and volume.dtype == np.float32
    assert model.exemplars == {"front": (20, 20, 3), "right": (20, 20, 3), "top": (20, 20, 3)}


def _stand_in_vgg(path, width: int = 2):
    """A VGG-19 features state_dict with torchvision's layout and ``width`` channels per layer."""
    state, previous = {}, 3
    torch.manual_seed(0)
    for i in VGG19_CONVS:
        state[f"features.{i}.weight"] = torch.randn(width, previous, 3, 3) * 0.3
        state[f"features.{i}.bias"] = torch.zeros(width)
        previous = width
    torch.save(state, path)


def test_a_local_vgg19_file_is_used(tmp_path, exemplar, tiny_options):
    weights = tmp_path / "vgg19.pth"
    _stand_in_vgg(weights)
    options = {**tiny_options, "descriptor": "vgg19", "vgg19_weights": str(weights), "slice_size": 32}
    model = neural.train(np.pad(exemplar, 4), rng=0, **options)
    assert len(model.history) == 3 and all(np.isfinite(model.history))
    assert model.config.descriptor == "vgg19"


def test_a_bad_vgg19_file_is_one_clear_error(tmp_path, exemplar, tiny_options):
    weights = tmp_path / "vgg19.pth"
    torch.save({"features.0.weight": torch.zeros(2, 3, 3, 3)}, weights)
    with pytest.raises(ParameterError, match="not a VGG-19 features state_dict"):
        neural.train(exemplar, descriptor="vgg19", vgg19_weights=str(weights), **tiny_options)
    with pytest.raises(ParameterError, match="vgg19_weights must be an existing file"):
        neural.train(exemplar, descriptor="vgg19", vgg19_weights=str(tmp_path / "none.pth"), **tiny_options)


def test_model_files_round_trip(tmp_path, exemplar, tiny_options):
    model = neural.train(exemplar, rng=0, **tiny_options)
    path = tmp_path / "m.pt"
    neural.save_model(model, path)
    loaded = neural.load_model(path)
    assert loaded.config == model.config and loaded.history == model.history
    np.testing.assert_array_equal(neural.generate(model, (-3, 4, 5), 12), neural.generate(loaded, (-3, 4, 5), 12))
    assert not np.array_equal(neural.generate(model, 0, 8), neural.generate(model, 0, 8, seed=9))
    (tmp_path / "bad.pt").write_bytes(b"junk")
    with pytest.raises(ParameterError, match="cannot be read as a neural model"):
        neural.load_model(tmp_path / "bad.pt")
    with pytest.raises(ParameterError, match="model must be an existing model file"):
        neural.load_model(tmp_path / "missing.pt")


@pytest.mark.parametrize("kwargs, message", [
    (dict(iterations=0), "iterations must be between 1 and"),
    (dict(tile=18), r"tile must be a multiple of 2\*\*\(scales-1\) = 4; got 18"),
    (dict(descriptor="gatys"), "descriptor must be one of random, vgg19; got 'gatys'"),
    (dict(learning_rate=-1), r"learning_rate must be a finite number in \(0.0, 10.0\]; got -1.0"),
    (dict(views="front,front"), "views must not repeat a view"),
    (dict(slice_size=4), "slice_size must be between 8 and 1024; got 4"),
])
def test_bad_options_name_the_parameter(exemplar, tiny_options, kwargs, message):
    with pytest.raises(ParameterError, match=message):
        neural.train(exemplar, **{**tiny_options, **kwargs})


def test_generate_checks_its_arguments(exemplar, tiny_options):
    model = neural.train(exemplar, rng=0, **tiny_options)
    with pytest.raises(ParameterError, match=r"shape must be >= 1; got 0"):
        neural.generate(model, (0, 0, 0), (4, 0, 4))
    with pytest.raises(ParameterError, match=r"origin must be an integer or three integers; got \(1, 2\)"):
        neural.generate(model, (1, 2), 4)
    with pytest.raises(ParameterError, match="this run needs about .* of memory"):
        neural.generate(model, 0, 100_000)


def test_a_finished_checkpoint_extends_to_more_steps(tmp_path, exemplar, tiny_options):
    path = tmp_path / "train.ckpt"
    neural.train(exemplar, rng=1, checkpoint=path, **{**tiny_options, "iterations": 2})
    extended = neural.train(exemplar, rng=1, checkpoint=path, **{**tiny_options, "iterations": 4})
    straight = neural.train(exemplar, rng=1, **{**tiny_options, "iterations": 4})
    assert extended.history == straight.history
    np.testing.assert_array_equal(neural.generate(extended, 0, 16), neural.generate(straight, 0, 16))
