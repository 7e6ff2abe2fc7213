"""The calibration map of the neural method: a monotone per-channel map
from the raw output's quantiles to the exemplar's, applied pointwise after generation."""

from __future__ import annotations

import json

import numpy as np
import torch

from npmrf3d.cli.main import main
from npmrf3d.methods import neural
from npmrf3d.methods.neural import engine
from tests_neural.helpers import random_model


def _w2(values, exemplar) -> float:
    """1-D Wasserstein-2 distance of two samples' value distributions (numpy, independent)."""
    q = (np.arange(2000) + 0.5) / 2000
    return float(np.sqrt(np.mean((np.quantile(values, q) - np.quantile(exemplar, q)) ** 2)))


def _bimodal(seed=3, channels=1):
    rng = np.random.default_rng(seed)
    a = np.where(rng.random((24, 24, channels)) < 0.3, 0.9, 0.15).astype(np.float32)
    return a + rng.normal(0, 0.02, a.shape).astype(np.float32)


def test_calibrated_values_follow_the_exemplars_distribution(tiny_options):
    exemplar = _bimodal()
    options = {**tiny_options, "iterations": 10, "seed": 0}
    raw = neural.train(exemplar, rng=0, calibrate=False, **options)
    fitted = neural.train(exemplar, rng=0, **options)
    assert raw.calibration is None
    table = fitted.calibration
    assert table.shape == (1, 2, engine.CALIBRATION_QUANTILES) and table.dtype == np.float32
    assert (np.diff(table[0, 0]) > 0).all()  # strictly increasing: a function
    pooled = np.concatenate([exemplar.ravel()] * 3)  # the three views' exemplars, pooled
    np.testing.assert_allclose(table[0, 1], np.quantile(pooled, np.linspace(0, 1, table.shape[2])),
                               rtol=1e-6, atol=1e-6)
    # the same network: calibration changes only the values, not the weights
    for a, b in zip(raw.generator.state_dict().values(), fitted.generator.state_dict().values()):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    before = neural.generate(raw, (100, -40, 7), 24)  # a block away from the calibration block
    after = neural.generate(fitted, (100, -40, 7), 24)
    d_raw, d_fit = _w2(before.ravel(), exemplar.ravel()), _w2(after.ravel(), exemplar.ravel())
    assert d_fit < 0.3 * d_raw, (d_fit, d_raw)
    assert after.min() >= exemplar.min() - 1e-6 and after.max() <= exemplar.max() + 1e-6
    # monotone: the order of the raw values is kept (ties aside)
    r, f = before.ravel(), after.ravel()
    order = np.argsort(r, kind="stable")
    assert (np.diff(f[order]) >= 0).all()


def test_a_calibrated_model_still_tiles_bit_for_bit():
    model = random_model(16, scales=4)
    levels = np.linspace(0, 1, 33)
    model.calibration = np.stack([np.stack([np.linspace(-3, 3, 33), levels ** 2]) for _ in range(3)]).astype(np.float32)
    whole = neural.generate(model, (0, 0, 0), 32)
    assembled = np.empty_like(whole)
    for i in (0, 16):
        for j in (0, 16):
            for k in (0, 16):
                assembled[i:i + 16, j:j + 16, k:k + 16] = neural.generate(model, (i, j, k), 16)
    np.testing.assert_array_equal(whole, assembled)
    model.calibration = None
    assert not np.array_equal(neural.generate(model, (0, 0, 0), 32), whole)


def test_the_map_is_saved_and_old_files_load_without_it(tmp_path, exemplar_rgb, tiny_options):
    model = neural.train(exemplar_rgb, rng=0, **tiny_options)
    assert model.calibration.shape == (3, 2, engine.CALIBRATION_QUANTILES)
    neural.save_model(model, tmp_path / "m.pt")
    loaded = neural.load_model(tmp_path / "m.pt")
    np.testing.assert_array_equal(loaded.calibration, model.calibration)
    np.testing.assert_array_equal(loaded.colour_basis, model.colour_basis)
    np.testing.assert_array_equal(neural.generate(loaded, 5, 12), neural.generate(model, 5, 12))
    payload = engine._payload(model)
    del payload["calibration"], payload["colour_basis"]
    settings = json.loads(payload["config"])
    del settings["calibrate"]
    payload["config"] = json.dumps(settings)
    torch.save(payload, tmp_path / "old.pt")
    old = neural.load_model(tmp_path / "old.pt")
    assert old.calibration is None and old.colour_basis is None and old.config.calibrate is False


def test_the_command_line_can_leave_it_out(tmp_path, exemplar):
    np.save(tmp_path / "ex.npy", exemplar)
    argv = ["neural", "train", str(tmp_path / "ex.npy"), "--quiet", "--iterations", "1", "--size", "16",
            "--scales", "3", "--channel-step", "2", "--noise-channels", "2", "--tile", "16", "--filters", "4",
            "--descriptor-scales", "2", "--filter-size", "3", "--threads", "1"]
    assert main([*argv, "--out", str(tmp_path / "a.pt")]) == 0
    assert main([*argv, "--out", str(tmp_path / "b.pt"), "--no-calibrate"]) == 0
    assert neural.load_model(tmp_path / "a.pt").calibration is not None
    assert neural.load_model(tmp_path / "b.pt").calibration is None
    assert neural.make_neural_config().calibrate is True


def _off_line(colours, origin, direction) -> np.ndarray:
    d = colours.reshape(-1, 3) - origin
    return np.linalg.norm(d - np.outer(d @ direction, direction), axis=1)


def test_colours_are_mapped_per_principal_component_and_stay_in_the_exemplars_gamut(tiny_options):
    """An exemplar whose colours all lie on one line of RGB space (a brown-to-cream ramp, two
    modes): after calibration the generated colours lie on that line too. A map per channel
    (the same quantile matching, written here independently) leaves it: it pairs one channel's
    high values with another's low ones, colours the exemplar does not have."""
    rng = np.random.default_rng(4)
    origin, direction = np.array([0.30, 0.18, 0.10]), np.array([0.6, 0.6, 0.52])
    direction /= np.linalg.norm(direction)
    t = np.where(rng.random((24, 24)) < 0.4, 0.9, 0.2) + rng.normal(0, 0.03, (24, 24))
    exemplar = (origin + t[..., None] * direction).astype(np.float32)
    model = neural.train(exemplar, rng=0, **{**tiny_options, "iterations": 4, "seed": 1})
    basis = model.colour_basis
    assert basis.shape == (4, 3)
    np.testing.assert_allclose(basis[:3] @ basis[:3].T, np.eye(3), atol=1e-5)  # orthonormal
    np.testing.assert_allclose(np.abs(basis[0]), direction, atol=1e-3)          # the ramp's axis
    np.testing.assert_allclose(basis[3], exemplar.reshape(-1, 3).mean(axis=0), atol=1e-5)
    block = neural.generate(model, (40, -8, 3), 20)
    assert _off_line(block, origin, direction).max() < 1e-3
    raw = engine._raw_block(model, (40, -8, 3), (20, 20, 20), None).reshape(-1, 3)
    calib = engine._raw_block(model, (0, 0, 0), (engine.CALIBRATION_SIDE,) * 3, None).reshape(-1, 3)
    q = np.linspace(0, 1, 257)
    pooled = np.concatenate([exemplar.reshape(-1, 3)] * 3)
    per_channel = np.stack([np.interp(raw[:, c], np.quantile(calib[:, c], q), np.quantile(pooled[:, c], q))
                            for c in range(3)], axis=1)
    assert np.median(_off_line(per_channel, origin, direction)) > 10 * np.median(_off_line(block, origin, direction)) + 1e-3
