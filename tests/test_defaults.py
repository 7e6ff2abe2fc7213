"""Every default is written once: the API, the configuration and the command line agree.

For each method of :data:`npmrf3d.methods.METHODS` with a sub-command, every option of the
sub-command that is a field of the method's configuration must default to that field's
default, and so must the same keyword of the public function and of ``make_config``.
"""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from npmrf3d import kopf_synthesize, synthesize
from npmrf3d.cli import build_parser
from npmrf3d.config import DEFAULT_SIZE, SynthesisConfig
from npmrf3d.methods import METHODS, get_method
from npmrf3d.methods.chen_wang import ChenWangConfig, chen_wang_synthesize, make_chen_wang_config
from npmrf3d.methods.kopf import KopfConfig, make_kopf_config
from npmrf3d.methods.npmrf import make_config
from npmrf3d.methods.npmrf_3d import (
    NpmrfVolumeConfig,
    make_npmrf_volume_config,
    npmrf_volume_synthesize,
)
from npmrf3d.methods.npmrf_coherent import CoherentConfig, coherent_synthesize, make_coherent_config
from npmrf3d.methods.volume_lh import VolumeConfig, make_volume_config, volume_synthesize
from npmrf3d.model.relax import RELAXATIONS


def _sub_parser(*path):
    parser = build_parser()
    for name in path:
        action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parser = action.choices[name]
    return parser


def _cli_defaults(*path) -> dict:
    return {a.dest: a.default for a in _sub_parser(*path)._actions if a.dest != "help"}


def _signature_defaults(fn) -> dict:
    return {name: p.default for name, p in inspect.signature(fn).parameters.items()
            if p.default is not inspect.Parameter.empty}


def _field_defaults(cls) -> dict:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
    return out


def _as_cli(value):
    """How the command line spells a default (tuples of views are comma-separated)."""
    if isinstance(value, tuple):
        return ",".join(str(v) for v in value)
    return value


CASES = {
    "npmrf": (("synth",), synthesize, make_config, SynthesisConfig),
    "kopf": (("baseline", "kopf"), kopf_synthesize, make_kopf_config, KopfConfig),
    "chen-wang": (("baseline", "chen-wang"), chen_wang_synthesize, make_chen_wang_config, ChenWangConfig),
    "coherent": (("coherent",), coherent_synthesize, make_coherent_config, CoherentConfig),
    "volume-lh": (("volume",), volume_synthesize, make_volume_config, VolumeConfig),
    "npmrf-3d": (("volume-npmrf",), npmrf_volume_synthesize, make_npmrf_volume_config, NpmrfVolumeConfig),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_api_config_and_cli_agree_on_every_default(name):
    path, public, builder, config_class = CASES[name]
    assert get_method(name).config_class is config_class
    fields = _field_defaults(config_class)
    cli = _cli_defaults(*path)
    api = _signature_defaults(public)
    made = _signature_defaults(builder)
    # options whose default is decided elsewhere on purpose
    special = {"upsample", "variant"} if name == "npmrf" else {"iterations"} if name == "kopf" else set()
    checked = 0
    for field, value in fields.items():
        if field in special or field in ("seed", "constrained", "rule"):
            continue
        if field in api:
            assert api[field] == value, f"{name}: API default of {field}"
        if field in made:
            assert made[field] == value, f"{name}: make_config default of {field}"
        if field in cli:
            cli_value = cli[field]
            expected = _as_cli(value)
            if isinstance(cli_value, str) and not isinstance(expected, str):
                expected = str(expected)
            assert cli_value == expected, f"{name}: CLI default of --{field.replace('_', '-')}"
            checked += 1
    assert checked >= 8
    if name in ("npmrf", "kopf"):
        assert cli["size"] == str(DEFAULT_SIZE) == str(api["size"]) == str(made["size"])
    else:  # the coherent methods default to the paper's scale, 64^3
        assert cli["size"] == _as_cli(config_class.size) and made["size"] == config_class.size


def test_special_defaults_agree_too():
    # NP-MRF up-sampling: None everywhere means "the relaxation's choice"
    assert _signature_defaults(synthesize)["upsample"] is None
    assert _signature_defaults(make_config)["upsample"] is None
    assert _cli_defaults("synth")["upsample"] is None
    # NP-MRF variant: None everywhere means "the relaxation's choice" (coherent for icm)
    assert _signature_defaults(synthesize)["variant"] is None
    assert _signature_defaults(make_config)["variant"] is None
    assert _cli_defaults("synth")["variant"] is None
    assert make_config().variant == SynthesisConfig.variant == "coherent"
    # NP_K iterations: one number for every level
    one = _signature_defaults(kopf_synthesize)["iterations"]
    assert one == _signature_defaults(make_kopf_config)["iterations"]
    assert _cli_defaults("baseline", "kopf")["iterations"] == str(one)
    assert KopfConfig.iterations == (one,) * KopfConfig.levels


def test_relaxation_options_are_the_configuration_defaults():
    for relaxation in RELAXATIONS.values():
        for field, value in _field_defaults(relaxation.options).items():
            assert getattr(SynthesisConfig, field) == value


def test_every_registered_method_has_the_common_signature():
    for method in METHODS.values():
        params = inspect.signature(method.run).parameters
        assert list(params)[:3] == ["per_view", "config", "rng"]
        assert {"progress", "checkpoint"} <= set(params)
        assert params["progress"].kind is inspect.Parameter.KEYWORD_ONLY


def test_unknown_method_lists_the_registered_ones():
    from npmrf3d.errors import ParameterError

    with pytest.raises(ParameterError, match="method must be one of npmrf, coherent, kopf, chen-wang, volume-lh, npmrf-3d, neural; got 'nope'"):
        get_method("nope")
    assert get_method("np_k") is METHODS["kopf"]
