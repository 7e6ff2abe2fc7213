"""Every default is written once: the API, the configuration and the command line agree.

For each method of :data:`npmrf3d.methods.METHODS` with a sub-command, every option of the
sub-command that is a field of the method's configuration must default to that field's
default, and so must the same keyword of the public function and of ``make_config``.
"""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from npmrf3d import kopf_synthesize, npmrf_synthesize, synthesize
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
    "npmrf": (("synth",), npmrf_synthesize, make_config, SynthesisConfig),
    "kopf": (("baseline", "kopf"), kopf_synthesize, make_kopf_config, KopfConfig),
    "chen-wang": (("baseline", "chen-wang"), chen_wang_synthesize, make_chen_wang_config, ChenWangConfig),
    "coherent": (("coherent",), coherent_synthesize, make_coherent_config, CoherentConfig),
    "volume-lh": (("volume",), volume_synthesize, make_volume_config, VolumeConfig),
    "npmrf-3d": (("volume-npmrf",), npmrf_volume_synthesize, make_npmrf_volume_config, NpmrfVolumeConfig),
}

#: The leading keywords every method's public function shares, with their defaults.
COMMON = {"exemplar": None, "size": DEFAULT_SIZE, "rng": None, "progress": None, "checkpoint": None,
          "exemplars": None}


@pytest.mark.parametrize("name", sorted(METHODS))
def test_every_public_function_has_the_one_shape(name):
    params = inspect.signature(METHODS[name].synthesize).parameters
    assert list(params)[:len(COMMON)] == list(COMMON)
    assert {k: params[k].default for k in COMMON} == COMMON
    assert list(params.values())[-1].kind is inspect.Parameter.VAR_KEYWORD
    dispatch = inspect.signature(synthesize).parameters
    assert list(dispatch)[:2] == ["exemplar", "method"] and dispatch["size"].default == DEFAULT_SIZE


@pytest.mark.parametrize("name", sorted(CASES))
def test_config_make_config_and_cli_agree_on_every_default(name):
    path, public, builder, config_class = CASES[name]
    assert get_method(name).config_class is config_class and get_method(name).synthesize is public
    fields = _field_defaults(config_class)
    cli = _cli_defaults(*path)
    made = _signature_defaults(builder)
    # options whose default is decided elsewhere on purpose
    special = ({"upsample", "support", "preset", "temperatures", "xi", "sampler", "blockwise",
                "phase_weight"} if name == "npmrf"
               else {"iterations"} if name == "kopf" else set())
    checked = 0
    for field, value in fields.items():
        if field in special or field in ("seed", "constrained", "rule", "size"):
            continue
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
    # one default size for every method, the API's, the configuration's and the command line's
    assert cli["size"] in (str(DEFAULT_SIZE), ",".join([str(DEFAULT_SIZE)] * 3))
    assert made["size"] in (DEFAULT_SIZE, (DEFAULT_SIZE,) * 3)


def test_special_defaults_agree_too():
    # NP-MRF up-sampling: None everywhere means "the relaxation's choice"
    assert _signature_defaults(make_config)["upsample"] is None
    assert _cli_defaults("synth")["upsample"] is None
    # NP-MRF support and preset: None everywhere means coherent (and tuned for support full)
    for name in ("variant", "support", "preset"):
        assert _signature_defaults(make_config)[name] is None
        assert _cli_defaults("synth")[name] is None
    assert make_config().support == SynthesisConfig.support == "coherent"
    assert make_config(relaxation="anneal").support == "coherent"
    assert make_config(support="full").preset == SynthesisConfig.preset == "tuned"
    # NP-MRF phase control: None everywhere means the configuration's weight (0 where it cannot run)
    assert _signature_defaults(make_config)["phase_weight"] is None
    assert _cli_defaults("synth")["phase_weight"] is None
    assert make_config().phase_weight == SynthesisConfig.phase_weight > 0
    assert make_config(blockwise=True).phase_weight == SynthesisConfig.phase_weight
    assert make_config(support="full").phase_weight == 0.0
    # NP_K iterations: one number for every level
    one = _signature_defaults(make_kopf_config)["iterations"]
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


def test_one_function_reaches_every_method_and_refuses_an_unknown_option():
    import numpy as np

    from npmrf3d.errors import ParameterError
    from tests.conftest import checkerboard

    image = checkerboard()
    through = synthesize(image, method="kopf", size=8, window=4, levels=1, iterations=1, rng=1).volume
    direct = kopf_synthesize(image, size=8, window=4, levels=1, iterations=1, rng=1).volume
    np.testing.assert_array_equal(through, direct)
    with pytest.raises(ParameterError, match="method kopf has no option 'xi'; its options are window, "):
        synthesize(image, method="kopf", size=8, xi=-1.0)
    with pytest.raises(ParameterError, match="needs a 3D exemplar"):
        synthesize(method="volume-lh", size=16)


def test_every_method_is_a_command_by_its_registry_name():
    commands = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    assert set(METHODS) <= set(commands.choices)
    for name in ("kopf", "chen-wang"):  # also under 'baseline', as before
        assert _sub_parser("baseline", name)._actions


def test_the_supports_own_defaults_are_written_once():
    """``xi`` and ``sampler`` default by support (:data:`DEFAULT_XI`, :data:`DEFAULT_SAMPLER`):
    what a configuration gets, the command line's help says."""
    from npmrf3d.methods.npmrf_options import DEFAULT_SAMPLER, DEFAULT_XI, make_config

    assert DEFAULT_XI == {"full": -3.0, "coherent": -1.0}
    assert DEFAULT_SAMPLER == {"full": "heat-bath", "coherent": "metropolis"}
    for support in ("full", "coherent"):
        icm = make_config(size=16, levels=2, window=5, support=support, temperatures=True)
        anneal = make_config(size=16, levels=2, window=5, support=support, relaxation="anneal")
        assert icm.xi == DEFAULT_XI[support] and anneal.sampler == DEFAULT_SAMPLER[support]



def test_the_default_site_spacing_follows_the_run():
    """Every 2nd site on a photograph whose levels all have even sides; every site for a
    segmented exemplar or odd sides; a spacing given is kept."""
    from npmrf3d.methods.npmrf_options import SPARSE_GRID, coherent_grid, make_config
    assert coherent_grid(make_config(size=64), False, 3) == SPARSE_GRID == 2
    assert coherent_grid(make_config(size=64), True, 3) == 1
    assert coherent_grid(make_config(size=36), False, 3) == 1  # level 2 has 9 voxels per side
    assert coherent_grid(make_config(size=36), False, 2) == 2
    assert coherent_grid(make_config(size=64, grid=1), False, 3) == 1
    assert coherent_grid(make_config(size=64, grid=2), True, 3) == 2


def test_the_default_levels_follow_the_exemplar_and_the_volume():
    """3 levels up to 64 pixels and voxels; one more for each doubling of both the exemplar's and
    the volume's smallest side while every side halves evenly; levels given are kept; the public
    functions' preparation settles them."""
    import numpy as np

    from npmrf3d.methods._api import prepare
    from npmrf3d.methods.npmrf import METHOD
    from npmrf3d.methods.npmrf_options import BASE_LEVELS, pyramid_levels, settle

    assert SynthesisConfig.levels is None and BASE_LEVELS == 3
    assert [pyramid_levels((n,) * 3, side) for n, side in ((64, 64), (128, 64), (64, 128), (128, 128),
                                                           (256, 256), (256, 128), (1024, 1024))] == [3, 3, 3, 4, 5, 4, 7]
    assert pyramid_levels((128, 128, 96), 256) == 3 and pyramid_levels((132,) * 3, 256) == 3  # 96 < 128; 132 / 8 is odd
    rng = np.random.default_rng(0)
    big, small = rng.random((128, 130)), rng.random((64, 64))
    unsettled = make_config(size=128)
    assert unsettled.levels is None
    assert settle(unsettled, {"front": big, "right": big, "top": big}).levels == 4
    assert settle(unsettled, {"front": big, "right": small, "top": big}).levels == 3  # the smallest exemplar
    assert settle(make_config(size=128, levels=2), {"front": big}).levels == 2
    config, _, _ = prepare(METHOD, big, None, size=128, rng=0, options={}, memory=False)
    assert config.levels == 4
    config, _, _ = prepare(METHOD, big, None, size=64, rng=0, options={}, memory=False)
    assert config.levels == 3


@pytest.mark.parametrize("size, levels", [(128, 4), (64, 3)])
def test_the_dry_run_names_the_settled_levels(capsys, tmp_path, size, levels):
    from npmrf3d import cli

    assert cli.main(["synth", "bundled:brick", "--size", str(size), "--dry-run", "--out", str(tmp_path / "o")]) == 0
    assert f"npmrf {size}x{size}x{size}, {levels} levels: needs about" in capsys.readouterr().out


@pytest.mark.parametrize("name", ["npmrf", "kopf", "chen-wang", "coherent", "volume-lh", "npmrf-3d"])
@pytest.mark.parametrize("keyword, value, words", [("progress", 5, "progress must be a callable"),
                                                   ("checkpoint", 5, "checkpoint must be a file path")])
def test_every_method_refuses_a_bad_progress_or_checkpoint_before_any_work(name, keyword, value, words):
    from npmrf3d import data
    from npmrf3d.errors import ParameterError

    exemplar = data.path("fibres48") if name in ("volume-lh", "npmrf-3d") else None
    with pytest.raises(ParameterError, match=words):
        METHODS[name].synthesize(exemplar, size=16, **{keyword: value})


@pytest.mark.parametrize("name, options", [("volume-lh", {"angle": 90}), ("volume-lh", {"angle": 90, "vector_field": "radial"}),
                                           ("npmrf-3d", {"angle": 90})])
def test_an_angle_that_turns_no_field_is_refused(name, options):
    from npmrf3d import data
    from npmrf3d.errors import ParameterError

    with pytest.raises(ParameterError, match="angle"):
        METHODS[name].synthesize(data.path("fibres48"), size=16, levels=2, rng=0, **options)
