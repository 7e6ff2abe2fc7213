"""The command reference pages are what the parsers say, and the options are written once.

``docs/commands/*.md`` are written by :mod:`npmrf3d.cli.reference` from the parsers, whose
method options come from the configurations' fields (:mod:`npmrf3d.options`); a page that no
longer matches (an option added, a default changed) fails here with the command that rewrites it.
"""

from __future__ import annotations

import dataclasses
import pathlib

import pytest

from npmrf3d.cli import build_parser
from npmrf3d.cli._generic import method_options
from npmrf3d.cli.reference import COMMAND_PAGES, command_page
from npmrf3d.config import SynthesisConfig
from npmrf3d.errors import ParameterError
from npmrf3d.methods.chen_wang import ChenWangConfig
from npmrf3d.methods.npmrf_coherent import CoherentConfig
from npmrf3d.options import field_default, option, options_of, refusing, validate

DOCS = pathlib.Path(__file__).resolve().parents[1] / "docs" / "commands"


@pytest.mark.parametrize("name", sorted(COMMAND_PAGES))
def test_each_reference_page_is_what_its_parser_says(name):
    page = DOCS / f"{name}.md"
    assert page.is_file(), f"missing {page}: run python -m npmrf3d.cli.reference docs/commands"
    assert page.read_text(encoding="utf-8") == command_page(name, build_parser()), (
        f"{page} is out of date: run python -m npmrf3d.cli.reference docs/commands")


@pytest.mark.parametrize("config_class", [SynthesisConfig, CoherentConfig, ChenWangConfig])
def test_every_field_is_an_option_with_help(config_class):
    fields = {f.name for f in dataclasses.fields(config_class)}
    assert set(options_of(config_class)) == fields
    for name, (_, opt) in method_options(config_class).items():
        assert opt.help and not opt.help.endswith("."), name
        assert (opt.applies is None) == (not opt.needs), name


@pytest.mark.parametrize("command, config_class", [("synth", SynthesisConfig), ("coherent", CoherentConfig),
                                                   ("chen-wang", ChenWangConfig)])
def test_the_command_line_takes_every_option_with_the_fields_default(command, config_class):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction").choices[command]
    actions = {a.dest: a for a in sub._actions}
    for name, (f, opt) in method_options(config_class).items():
        assert name in actions, name
        if opt.decided is None and opt.kind != "levels":
            assert actions[name].default == field_default(f), name
        elif opt.decided is not None:
            assert actions[name].default is None and opt.decided in actions[name].help, name


def test_synth_help_fits_a_screenful(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["synth", "--help"])
    assert len(capsys.readouterr().out.splitlines()) <= 120


def test_limits_and_choices_come_from_the_field():
    assert validate(ChenWangConfig, "k", 64) == 64
    with pytest.raises(ParameterError, match="k must be between 1 and 64; got 65"):
        validate(ChenWangConfig, "k", 65)
    with pytest.raises(ParameterError, match="solver must be one of mean, medoid"):
        validate(ChenWangConfig, "solver", "median")
    with pytest.raises(ParameterError, match="stop must be a finite number in"):
        validate(CoherentConfig, "stop", 0.0)


def test_an_option_a_run_would_not_read_is_refused_through_the_api_only():
    """The user's call refuses it; a method translating its options into another's does not."""
    from npmrf3d.methods.npmrf_coherent import make_coherent_config

    assert make_coherent_config(size=16, levels=2, sampler="metropolis").sampler == "metropolis"
    checked = refusing(make_coherent_config, CoherentConfig)
    with pytest.raises(ParameterError, match="option sampler changes nothing unless option t0 is above 0"):
        checked(size=16, levels=2, sampler="metropolis")
    assert checked(size=16, levels=2, t0=1.0, sampler="metropolis").sampler == "metropolis"
    with pytest.raises(ParameterError, match="option pilot changes nothing unless option blockwise is set"):
        checked(size=16, levels=2, pilot=32)


def test_a_new_option_is_one_field():
    """What adding an option costs: one field; the command line, its help and its checks follow."""
    import argparse

    from npmrf3d.cli._generic import _add_option, config_options

    @dataclasses.dataclass(frozen=True)
    class Toy:
        smoothing: float = option(0.5, "how smooth", kind="real", low=0.0, high=1.0)
        passes: int = option(2, "passes over the volume", kind="int", low=1, applies=lambda c: c.smoothing > 0,
                             needs="smoothing is above 0")

    parser = argparse.ArgumentParser()
    for name, (f, opt) in method_options(Toy).items():
        _add_option(parser, name, f, opt)
    args = parser.parse_args(["--smoothing", "0.25"])
    assert config_options(args, Toy) == {"smoothing": 0.25, "passes": 2}
    with pytest.raises(ParameterError, match="smoothing must be a finite number in"):
        validate(Toy, "smoothing", 2.0)
    assert "passes over the volume" in parser.format_help()
