"""Options written once: each option of a method is one field of its frozen configuration.

A configuration dataclass declares an option with :func:`option`: its default, one line of help,
its limits or choices, where the command line lists it, and -- for an option that only some runs
read -- the condition under which it applies. Everything else reads these fields and nothing
else:

- the command line builds each command's options and ``--help`` from them
  (:func:`npmrf3d.cli._generic.add_method_parser`);
- :func:`validate` checks a value against the field's limits (with :mod:`npmrf3d._validation`'s
  messages), so a method's ``make_config`` only checks what ties several options together;
- :func:`refuse_inapplicable` refuses, in one line, an option set away from its default that the
  configuration would not read (``sampler`` without annealing, ``pilot`` without blocks);
- :func:`option_table` writes the docs' option tables;
- :func:`made_from` gives a method's ``make_config`` its keywords, one per option, with the
  fields' defaults, so that it validates a dict of every option rather than listing them;
- :func:`shared` carries a configuration into another method's, field by field, for every
  option the two have by name (the default method runs the coherent sampler so).

Adding an option to a method is one field here and its use in the method.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from . import _validation as check

__all__ = ["Option", "option", "options_of", "validate", "refuse_inapplicable", "given_options",
           "option_table", "flag_name", "recorded", "refusing", "same_option", "flat_options", "keywords",
           "made_from", "shared"]

_KEY = "npmrf3d_option"


@dataclass(frozen=True)
class Option:
    """What a configuration field says about itself as an option.

    Attributes
    ----------
    help : str
        One line for ``--help`` (the default is appended there).
    kind : str
        ``int``, ``real``, ``choice``, ``flag`` (a boolean set by ``--name``), ``levels`` (one
        integer or one per level, ``8,6,4``), ``text`` or ``own`` (the command handles it itself).
    low, high : number, optional
        Limits; ``low_open``/``high_open`` exclude them.
    choices : tuple of str or callable, optional
        The valid names (a callable is asked when first needed, so registries stay lazy).
    metavar : str, optional
        The command line's metavar (default: one for the kind, ``N``, ``X``, ``N[,N..]``).
    group : str
        The ``--help`` section.
    decided : str, optional
        The field's default is ``None`` and the run decides: the words ``--help`` shows as the
        default (the command line's default is then ``None`` too).
    applies : callable, optional
        ``applies(config) -> bool``: whether a run of ``config`` reads the option; ``needs`` says
        when, starting with the option it depends on (``"t0 is above 0"``).
    optional : bool
        ``None`` is a valid value (no limit checks then).
    """

    help: str
    kind: str = "own"
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | Callable[[], Iterable[str]] | None = None
    metavar: str | None = None
    group: str = "method"
    decided: str | None = None
    applies: Callable[[Any], bool] | None = None
    needs: str = ""
    optional: bool = False

    def names(self) -> tuple[str, ...]:
        """The valid choices."""
        return tuple(self.choices() if callable(self.choices) else self.choices or ())


def option(default=dataclasses.MISSING, help: str = "", *, default_factory=dataclasses.MISSING,
           **attributes) -> Any:
    """A dataclass field that is an option (see :class:`Option` for ``attributes``)."""
    meta = {_KEY: Option(help=help, **attributes)}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def same_option(config_class, name: str, default=dataclasses.MISSING, **changes) -> Any:
    """A field that is option ``name`` of ``config_class`` again (its help, limits, group), with
    another ``default`` or other ``changes`` where given: one method built on another's options
    writes only what differs."""
    f, opt = options_of(config_class)[name]
    return dataclasses.field(default=field_default(f) if default is dataclasses.MISSING else default,
                             metadata={_KEY: dataclasses.replace(opt, **changes)})


def options_of(config_class) -> dict[str, tuple[dataclasses.Field, Option]]:
    """{field name: (field, option)} of the fields of ``config_class`` that are options, in order."""
    return {f.name: (f, f.metadata[_KEY]) for f in dataclasses.fields(config_class) if _KEY in f.metadata}


def flat_options(config_class) -> dict[str, tuple[dataclasses.Field, Option]]:
    """:func:`options_of` with a nested configuration's options (the decision rule's) in its place."""
    out = {}
    for name, (f, opt) in options_of(config_class).items():
        out.update(options_of(type(field_default(f))) if opt.kind == "nested" else {name: (f, opt)})
    return out


def keywords(config_class, **more) -> dict[str, Any]:
    """{keyword: default} of ``config_class``'s ``make_config``: every option of
    :func:`flat_options` with its field's default, None where the run decides it
    (:attr:`Option.decided`), then ``more`` (keywords that are no field, or another default).

    >>> from npmrf3d.methods.chen_wang import ChenWangConfig
    >>> list(keywords(ChenWangConfig))[:4], keywords(ChenWangConfig)["k"]
    (['size', 'window', 'levels', 'views'], 5)
    """
    out = {name: None if opt.decided is not None else field_default(f)
           for name, (f, opt) in flat_options(config_class).items()}
    return {**out, **more}


def made_from(config_class, **more) -> Callable[[Callable[[dict], Any]], Callable[..., Any]]:
    """Decorator: ``build(values)``, which validates ``values`` -- a dict of every keyword of
    :func:`keywords` (``config_class``, ``more``) -- into a configuration, becomes
    ``make_config(**options)``, whose signature lists those keywords and defaults (so ``help``,
    ``inspect`` and the API's list of a method's options read them) and which refuses an unknown
    keyword in one line. An option added to ``config_class`` is a keyword at once.

    >>> from npmrf3d.methods.chen_wang import make_chen_wang_config
    >>> make_chen_wang_config(size=16, levels=2, k=3).k
    3
    >>> make_chen_wang_config(kk=3)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    npmrf3d.errors.ParameterError: there is no option 'kk'; the options are size, window, levels, views, ...
    """
    defaults = keywords(config_class, **more)

    def decorate(build: Callable[[dict], Any]) -> Callable[..., Any]:
        @functools.wraps(build)
        def make_config(**options):
            unknown = [name for name in options if name not in defaults]
            if unknown:
                check.fail(f"there is no option {unknown[0]!r}; the options are {', '.join(defaults)}")
            return build({**defaults, **options})

        make_config.__signature__ = inspect.Signature(
            [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=value)
             for name, value in defaults.items()])
        return make_config
    return decorate


def flat_values(config) -> dict[str, Any]:
    """{name: value} of every option of ``config``, a nested configuration's in its place."""
    out = {}
    for name, (_, opt) in options_of(type(config)).items():
        value = getattr(config, name)
        out.update(flat_values(value) if opt.kind == "nested" else {name: value})
    return out


def shared(config, target_class) -> dict[str, Any]:
    """The values of ``config``'s options (:func:`flat_values`) that ``target_class`` has by the
    same name, for the target's ``make_config``: one configuration carried into another field by
    field. A None that ``config`` leaves for the run to decide (:attr:`Option.decided`) is left
    out, so that the target's own default holds.

    >>> from npmrf3d.methods.npmrf_options import make_config
    >>> from npmrf3d.methods.npmrf_coherent import CoherentConfig
    >>> carried = shared(make_config(size=16, levels=2), CoherentConfig)
    >>> carried["levels"], carried["outlier"], "grid" in carried, "preset" in carried
    (2, 0.01, False, False)
    """
    fields, values = flat_options(type(config)), flat_values(config)
    return {name: values[name] for name in options_of(target_class)
            if name in values and not (values[name] is None and fields[name][1].decided is not None)}


def field_default(f: dataclasses.Field):
    """The default value of a dataclass field."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def flag_name(name: str) -> str:
    """The command line's spelling of option ``name`` (``max_sweeps`` -> ``--max-sweeps``)."""
    return "--" + name.replace("_", "-")


def validate(config_class, name: str, value, *, levels: int | None = None):
    """``value`` of option ``name`` of ``config_class`` checked against its field's limits and
    returned in its canonical type (one line, :class:`npmrf3d.ParameterError`, when it is not).

    >>> from npmrf3d.methods.chen_wang import ChenWangConfig
    >>> validate(ChenWangConfig, "k", 3)
    3
    >>> validate(ChenWangConfig, "k", 0)
    Traceback (most recent call last):
    ...
    npmrf3d.errors.ParameterError: k must be between 1 and 64; got 0
    """
    opt = options_of(config_class)[name][1]
    if value is None and opt.optional:
        return None
    if opt.kind == "int":
        return check.integer(name, value, low=opt.low, high=opt.high)
    if opt.kind == "real":
        return check.real(name, value, low=opt.low, high=opt.high, low_open=opt.low_open,
                          high_open=opt.high_open)
    if opt.kind == "choice":
        return check.choice(name, value, opt.names())
    if opt.kind == "flag":
        return check.boolean(name, value)
    if opt.kind == "levels":
        return check.per_level(name, value, levels, low=opt.low, high=opt.high)
    return value


def given_options(config_class, values: Mapping[str, Any]) -> list[str]:
    """The names among ``values`` whose value differs from the field's default (what a user set)."""
    fields = options_of(config_class)
    return [name for name, value in values.items()
            if name in fields and value is not None and value != field_default(fields[name][0])]


def refuse_inapplicable(config, given: Iterable[str]) -> None:
    """One line for the first option of ``given`` that a run of ``config`` would not read."""
    fields = options_of(type(config))
    for name in given:
        opt = fields[name][1] if name in fields else None
        if opt is not None and opt.applies is not None and not opt.applies(config):
            check.fail(f"option {name} changes nothing unless option {opt.needs}; drop it or change that")


def refusing(make_config: Callable[..., Any], config_class) -> Callable[..., Any]:
    """``make_config`` that also refuses an option set away from its default that the run would
    not read (:func:`refuse_inapplicable`): what the API and the command line call; a method that
    translates its options into another's calls the plain one."""
    @functools.wraps(make_config)
    def make(**values):
        config = make_config(**values)
        refuse_inapplicable(config, given_options(config_class, values))
        return config
    return make


def recorded(config) -> dict:
    """What a run of ``config`` read, for its record (``run.json``): every field but the options
    the run does not read (:attr:`Option.applies`), a nested configuration (the decision rule)
    likewise. Fields that are not options are kept as they are.

    >>> from npmrf3d.methods.npmrf_options import make_config
    >>> record = recorded(make_config(size=16, levels=2))
    >>> "preset" in record, "xi" in record, sorted(record["rule"])
    (False, False, ['centre_bandwidth', 'outlier'])
    """
    def read(opt) -> bool:
        return opt is None or opt.applies is None or opt.applies(config)

    out = {}
    for f in dataclasses.fields(config):
        opt = f.metadata.get(_KEY)
        if not read(opt):
            continue
        value = getattr(config, f.name)
        if opt is not None and opt.kind == "nested":
            value = {name: getattr(value, name) for name, (_, inner) in options_of(type(value)).items()
                     if read(inner)}
        elif dataclasses.is_dataclass(value):
            value = dataclasses.asdict(value)
        out[f.name] = value
    return out


def default_text(f: dataclasses.Field, opt: Option) -> str:
    """How ``--help`` and the docs state a field's default."""
    if opt.decided is not None:
        return opt.decided
    value = field_default(f)
    if isinstance(value, tuple):
        return ",".join(map(str, value))
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def option_table(config_class) -> str:
    """A Markdown table of the options of ``config_class``: option, default, meaning."""
    rows = ["| option | default | meaning |", "| --- | --- | --- |"]
    for name, (f, opt) in options_of(config_class).items():
        if opt.kind == "own":
            continue
        text = opt.help + (f" (applies when {flag_name(opt.needs)})" if opt.needs else "")
        rows.append(f"| `{flag_name(name)}` | {default_text(f, opt)} | {text.replace('|', '/')} |")
    return "\n".join(rows)
