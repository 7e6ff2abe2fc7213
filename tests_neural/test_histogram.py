"""The value-histogram term of the training loss: sorted slice values
against the exemplar's quantiles."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from npmrf3d.cli.main import main
from npmrf3d.errors import ParameterError
from npmrf3d.methods import neural
from npmrf3d.methods.neural import engine
from npmrf3d.methods.neural.descriptor import histogram_loss, histogram_target


def _w2(values, exemplar) -> float:
    """1-D Wasserstein-2 distance of two samples' value distributions (numpy, independent)."""
    q = (np.arange(2000) + 0.5) / 2000
    return float(np.sqrt(np.mean((np.quantile(values, q) - np.quantile(exemplar, q)) ** 2)))


def test_the_loss_is_zero_for_the_exemplars_own_values_in_any_order():
    rng = np.random.default_rng(0)
    exemplar = torch.from_numpy(rng.random((2, 8, 8)).astype(np.float32))
    target, spread = histogram_target(exemplar, 64)
    np.testing.assert_allclose(target.numpy(), np.sort(exemplar.reshape(2, -1).numpy(), axis=1), rtol=1e-6)
    shuffled = exemplar.reshape(2, -1)[:, torch.from_numpy(rng.permutation(64))].reshape(1, 2, 8, 8)
    assert float(histogram_loss(shuffled, target, spread)) < 1e-6
    # a shift by half a standard deviation of every value costs half a standard deviation
    shifted = shuffled + 0.5 * spread.reshape(1, 2, 1, 1)
    assert float(histogram_loss(shifted, target, spread)) == pytest.approx(0.5, rel=1e-4)


def test_the_target_is_the_exemplars_quantiles_at_another_pixel_count():
    exemplar = torch.from_numpy(np.random.default_rng(1).normal(size=(1, 40, 40)).astype(np.float32))
    target, spread = histogram_target(exemplar, 100)
    expected = np.quantile(exemplar.numpy().ravel(), (np.arange(100) + 0.5) / 100, method="hazen")
    np.testing.assert_allclose(target.numpy()[0], expected, atol=1e-5)
    assert float(spread) == pytest.approx(float(exemplar.std(unbiased=False)), rel=1e-5)


def test_the_loss_has_gradients_that_pull_values_towards_the_exemplars():
    target, spread = histogram_target(torch.linspace(0, 1, 16).reshape(1, 4, 4), 16)
    image = torch.full((1, 1, 4, 4), 2.0, requires_grad=True)
    histogram_loss(image, target, spread).backward()
    assert (image.grad > 0).all()  # every value is above the exemplar's: a step down lowers the loss


def test_training_with_the_term_matches_the_value_distribution_better(tiny_options):
    # a bimodal exemplar (dark background, bright grains): the Gram terms alone see only its mean
    # and covariance
    rng = np.random.default_rng(3)
    exemplar = np.where(rng.random((24, 24)) < 0.3, 0.9, 0.15).astype(np.float32)
    exemplar += rng.normal(0, 0.02, exemplar.shape).astype(np.float32)
    options = {**tiny_options, "iterations": 40, "seed": 0, "calibrate": False}  # the loss alone
    distances = {}
    for weight in (0.0, 2.0):
        model = neural.train(exemplar, rng=0, histogram_weight=weight, **options)
        volume = neural.generate(model, (0, 0, 0), 16)
        distances[weight] = _w2(volume.ravel(), exemplar.ravel())
    assert distances[2.0] < 0.75 * distances[0.0], distances  # measured: 0.138 vs 0.221


def test_the_weight_is_validated_recorded_and_set_on_the_command_line(tmp_path, exemplar, tiny_options):
    assert neural.make_neural_config().histogram_weight == 1.0
    with pytest.raises(ParameterError, match=r"histogram_weight must be a finite number in \[0.0, 1000.0\]; got -1.0"):
        neural.make_neural_config(histogram_weight=-1)
    np.save(tmp_path / "ex.npy", exemplar)
    out = tmp_path / "m.pt"
    argv = ["neural", "train", str(tmp_path / "ex.npy"), "--out", str(out), "--quiet", "--iterations", "1",
            "--size", "16", "--scales", "3", "--channel-step", "2", "--noise-channels", "2", "--tile", "16",
            "--filters", "4", "--descriptor-scales", "2", "--filter-size", "3", "--threads", "1"]
    assert main([*argv, "--histogram-weight", "0.25"]) == 0
    assert neural.load_model(out).config.histogram_weight == 0.25
    assert main([*argv, "--overwrite", "--histogram-weight", "-2"]) == 2


def test_a_model_file_from_before_the_term_loads_with_weight_zero(tmp_path, exemplar, tiny_options):
    model = neural.train(exemplar, rng=0, **tiny_options)
    payload = engine._payload(model)
    import json

    settings = json.loads(payload["config"])
    del settings["histogram_weight"]
    payload["config"] = json.dumps(settings)
    torch.save(payload, tmp_path / "old.pt")
    old = neural.load_model(tmp_path / "old.pt")
    assert old.config.histogram_weight == 0.0
    np.testing.assert_array_equal(neural.generate(old, 0, 8), neural.generate(model, 0, 8))
