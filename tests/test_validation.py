"""Every user mistake in ``synthesize`` raises ParameterError naming the parameter, before any
compiled work."""

from __future__ import annotations

import re

import numpy as np
import pytest

import npmrf3d
from npmrf3d import ParameterError
from npmrf3d.config import SUPPORTS
from npmrf3d.methods import npmrf
from npmrf3d.methods.npmrf_options import APPLIES, TEMPERATURE_OPTIONS, make_config


@pytest.fixture(autouse=True)
def no_compiled_work(monkeypatch):
    """Fail loudly if validation lets a bad call through to the synthesis itself."""

    def forbidden(*args, **kwargs):
        raise AssertionError("validation passed: synthesis started")

    monkeypatch.setattr(npmrf, "run", forbidden)
    monkeypatch.setattr(npmrf, "_run_coherent", forbidden)
    monkeypatch.setattr(npmrf, "build_view_models", forbidden)


@pytest.fixture
def grey():
    return np.random.default_rng(0).integers(0, 256, size=(16, 16), dtype=np.uint8)


@pytest.fixture
def rgb():
    return np.random.default_rng(1).integers(0, 256, size=(16, 16, 3), dtype=np.uint8)


GOOD = {"size": 8, "window": 3, "levels": 1, "rng": 0}


def call(exemplar, **kwargs):
    return npmrf3d.synthesize(exemplar, **{**GOOD, **kwargs})


def test_valid_call_reaches_synthesis(grey):
    """Control: the arguments used below are valid apart from the one each test breaks."""
    with pytest.raises(AssertionError, match="synthesis started"):
        call(grey)
    with pytest.raises(AssertionError, match="synthesis started"):
        call(grey, views=("front", "top"), exemplars={"top": grey.T.copy()})


# --------------------------------------------------------------------------- exemplar


@pytest.mark.parametrize(("shape", "window", "levels"), [((5, 5), 7, 1), ((16, 6), 7, 1),
                                                          ((16, 16), 7, 3)])
def test_exemplar_smaller_than_window(shape, window, levels):
    exemplar = np.zeros(shape, dtype=np.uint8)
    size = 2 ** (levels - 1) * (window // 2 + 1)
    with pytest.raises(ParameterError, match=rf"exemplar of size {shape[0]}x{shape[1]} is too "
                                             rf"small for window {window}"):
        call(exemplar, window=window, levels=levels, size=size)


@pytest.mark.parametrize("window", [4, 6, 1, 17, 0, -3])
def test_bad_window(grey, window):
    with pytest.raises(ParameterError, match=rf"window must be an odd integer between 3 and 15; "
                                             rf"got {window}"):
        call(grey, window=window)


def test_window_not_an_integer(grey):
    with pytest.raises(ParameterError, match="window must be an integer"):
        call(grey, window=3.0)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_exemplar(bad):
    exemplar = np.random.default_rng(0).random((16, 16)).astype(np.float32)
    exemplar[3, 4] = bad
    with pytest.raises(ParameterError, match="exemplar contains 1 NaN or Inf values"):
        call(exemplar)


def test_four_dimensional_exemplar():
    with pytest.raises(ParameterError, match=r"exemplar of shape \(4, 16, 16, 1\) is a volume .* from a 2D image"):
        call(np.zeros((4, 16, 16, 1)))


@pytest.mark.parametrize("shape", [(0, 16), (16, 0, 3)])
def test_empty_exemplar(shape):
    with pytest.raises(ParameterError, match="exemplar is empty"):
        call(np.zeros(shape))


def test_non_numeric_exemplar():
    with pytest.raises(ParameterError, match="exemplar must hold numbers"):
        call(np.full((16, 16), "a"))


def test_missing_file(tmp_path):
    path = tmp_path / "missing.png"
    with pytest.raises(ParameterError, match=r"exemplar file .*missing\.png.* does not exist"):
        call(str(path))
    with pytest.raises(ParameterError, match="does not exist"):
        call(path)


def test_unreadable_file(tmp_path):
    path = tmp_path / "garbage.png"
    path.write_bytes(b"this is not a png \x00\x01\x02" * 10)
    with pytest.raises(ParameterError, match=r"exemplar file .*garbage\.png.* cannot be read"):
        call(str(path))


def test_exemplar_is_a_directory(tmp_path):
    with pytest.raises(ParameterError, match="exemplar file .* is not a file"):
        call(str(tmp_path))


# --------------------------------------------------------------------------- names


def test_unknown_heuristic_lists_all_names(grey):
    with pytest.raises(ParameterError, match=r"heuristic must be one of .*; got 'ML_H3'") as info:
        call(grey, heuristic="ML_H3")
    for name in ("ML_H1a", "ML_H1b", "ML_H2a", "ML_H2b"):
        assert name in str(info.value)


def test_unknown_relaxation(grey):
    with pytest.raises(ParameterError, match=r"relaxation must be one of icm.*; got 'gibbs'"):
        call(grey, relaxation="gibbs")


def test_unknown_upsample(grey):
    with pytest.raises(ParameterError, match=r"upsample must be one of 1/8, 8/8; got '2/8'"):
        call(grey, upsample="2/8")


def test_unknown_inherit_variant_decision(grey):
    with pytest.raises(ParameterError, match="inherit must be one of resynth, fixed"):
        call(grey, inherit="frozen")
    with pytest.raises(ParameterError, match="variant must be one of"):
        call(grey, variant="best")
    with pytest.raises(ParameterError, match="decision must be one of argmax, sample"):
        call(grey, decision="metropolis")


# --------------------------------------------------------------------------- numbers


@pytest.mark.parametrize(("size", "levels"), [(30, 3), ((8, 8, 6), 3), (12, 4)])
def test_size_not_divisible(grey, size, levels):
    with pytest.raises(ParameterError, match=re.escape(f"is not divisible by 2**(levels-1) = "
                                                       f"{2 ** (levels - 1)}")):
        call(grey, size=size, levels=levels)


def test_size_shape(grey):
    with pytest.raises(ParameterError, match="size must be an integer or three integers"):
        call(grey, size=(8, 8))
    with pytest.raises(ParameterError, match="size must be positive"):
        call(grey, size=0)


@pytest.mark.parametrize("xi", [0, 0.0, 1, np.nan])
def test_bad_xi(grey, xi):
    with pytest.raises(ParameterError, match=r"xi must be a finite number in \(-inf, 0.0\)"):
        call(grey, xi=xi)


@pytest.mark.parametrize("stop", [0, 1.5, -0.1])
def test_bad_stop(grey, stop):
    with pytest.raises(ParameterError, match=r"stop must be a finite number in \(0.0, 1.0\]"):
        call(grey, stop=stop)


def test_bad_levels_and_sweeps(grey):
    with pytest.raises(ParameterError, match="levels must be between 1 and 8; got 0"):
        call(grey, levels=0)
    with pytest.raises(ParameterError, match="max_sweeps must be >= 1; got 0"):
        call(grey, max_sweeps=0)


def test_bad_rule_overrides(grey):
    with pytest.raises(ParameterError, match="bandwidth must be a finite number"):
        call(grey, bandwidth=0.0)
    with pytest.raises(ParameterError, match="tau must be a finite number"):
        call(grey, tau=-1.0)
    with pytest.raises(ParameterError, match="adaptive must be a finite number"):
        call(grey, adaptive=-0.5)


def test_negative_seed(grey):
    with pytest.raises(ParameterError, match="seed must be >= 0; got -1"):
        call(grey, rng=-1)


def test_bad_rng_type(grey):
    with pytest.raises(ParameterError, match="rng must be None, an integer seed or a numpy "
                                             "Generator"):
        call(grey, rng="seed")


# --------------------------------------------------------------------------- views


def test_empty_views(grey):
    with pytest.raises(ParameterError, match="views must name 1 to 3 of front, right, top"):
        call(grey, views=())
    with pytest.raises(ParameterError, match="views must name"):
        call(grey, views="")


def test_duplicated_views(grey):
    with pytest.raises(ParameterError, match="views must not repeat a view; got front, front"):
        call(grey, views=("front", "front"))
    with pytest.raises(ParameterError, match="views must not repeat"):
        call(grey, views="top,TOP")


def test_unknown_view(grey):
    with pytest.raises(ParameterError, match=r"view must be one of front, right, top; "
                                             r"got 'side'"):
        call(grey, views=("front", "side"))


def test_exemplar_for_unconstrained_view(grey):
    with pytest.raises(ParameterError, match="exemplars given for views that are not "
                                             "constrained: top"):
        call(grey, views=("front",), exemplars={"top": grey})
    with pytest.raises(ParameterError, match="not constrained: side"):
        call(grey, exemplars={"side": grey})


def test_channel_mismatch_between_views(grey, rgb):
    with pytest.raises(ParameterError, match=r"all exemplars must have the same number of "
                                             r"channels; got \[1, 3\]"):
        call(grey, views=("front", "top"), exemplars={"top": rgb})


def test_per_view_exemplar_is_validated_with_its_view_name(grey):
    bad = np.zeros((16, 16), dtype=np.float32)
    bad[0, 0] = np.nan
    with pytest.raises(ParameterError, match="exemplar for view top contains 1 NaN"):
        call(grey, views=("front", "top"), exemplars={"top": bad})
    with pytest.raises(ParameterError, match="exemplar for view top of size 2x2 is too small"):
        call(grey, views=("front", "top"), exemplars={"top": np.zeros((2, 2))})


@pytest.mark.parametrize("heuristic", ["ML_H1a", "ML_H1b"])
def test_sample_decision_needs_an_objective(grey, heuristic):
    with pytest.raises(ParameterError, match=rf"decision 'sample' needs a heuristic with an "
                                             rf"objective.*{heuristic}"):
        call(grey, heuristic=heuristic, decision="sample", variant="sharp")
    # the sharp variant samples: the same mistake without naming the decision
    with pytest.raises(ParameterError, match="decision 'sample'"):
        call(grey, heuristic=heuristic, variant="sharp")
    # the coherent support (the default) decides by the per-view rules with ICM, not with annealing
    with pytest.raises(ParameterError, match=f"heuristic {heuristic} cannot drive annealing"):
        call(grey, heuristic=heuristic, relaxation="anneal")


def test_parameter_error_is_a_value_error():
    assert issubclass(ParameterError, ValueError)


#: A value other than the default for every option that some combinations cannot use.
NON_DEFAULT = {"feature_weight": 1.0, "xi": -5.0, "stop": 0.5, "max_sweeps": 3, "inherit": "fixed",
               "sampler": "metropolis", "schedule": "linear", "t0": 2.0, "t_end": 0.1, "proposals": 3,
               "proposal": "labels", "preset": "paper", "bandwidth": 0.5, "adaptive": 0.1,
               "decision": "argmax", "tau": 0.5, "histogram_weight": 1.0, "toroidal_exemplar": True,
               "segmented": "yes", "temperatures": True, "phase_weight": 4.0}


@pytest.mark.parametrize("name", sorted(APPLIES))
def test_an_option_is_refused_where_it_cannot_apply_and_accepted_where_it_can(name):
    for support in SUPPORTS:
        for relaxation in ("icm", "anneal"):
            options = {"size": 16, "levels": 2, "support": support, "relaxation": relaxation,
                       name: NON_DEFAULT[name]}
            if (support, relaxation) in APPLIES[name]:
                if support == "coherent" and relaxation == "icm" and name in TEMPERATURE_OPTIONS:
                    with pytest.raises(ParameterError, match=f"option {name} needs per-voxel temperatures"):
                        make_config(**options)
                    options["temperatures"] = True
                assert getattr(make_config(**options), name, None) in (NON_DEFAULT[name], None)
            else:
                with pytest.raises(ParameterError, match=f"option {name} does not apply to support "
                                                         f"'{support}' with relaxation '{relaxation}'"):
                    make_config(**options)
