"""How the command line speaks of its options: which options the user wrote (a default is not
written), library parameter names in messages turned into option names, and the environment
settings checked before a command runs.

The library names its parameters (``max_sweeps``, ``r``, ``vector_field``); the command line's
messages name the options (``--max-sweeps``, ``--r``, ``--vector-field``), read from the parser
of the command that ran, so that no table can disagree with it.
"""

from __future__ import annotations

import argparse
import os
import re

from .._kernels._jit import THREAD_SETTING_PROBLEM, thread_setting_problem

__all__ = ["environment_problem", "given", "given_options", "option_strings", "speak_options"]


def speak_options(message: str, option_names=()) -> str:
    """A library message in the command line's words: a message that starts with a parameter
    name (``window must ...``, ``size 8 is ...``, ``vector_field contains ...``) or names one as
    ``option NAME`` calls it by its option (``--window``); a library spelling followed by the
    option in brackets, ``kind='image' (command line: --kind image)``, keeps the option only.

    ``option_names`` maps parameter names to option strings (``{"r": "--r"}``), or lists names
    whose option is ``--`` + the name with ``-`` for ``_``.

    >>> speak_options("max_sweeps must be >= 1; got 0", ("max_sweeps",))
    '--max-sweeps must be >= 1; got 0'
    >>> speak_options("option tau does not apply", {"tau": "--tau"})
    'option --tau does not apply'
    >>> speak_options("say so with kind='image' (command line: --kind image)")
    'say so with --kind image'
    """
    # "exemplar_kind='image' (command line: --exemplar-kind image)": the command line's part
    message = re.sub(r"\b[a-z_]+=(?:'[^']*'|\w+) \(command line: ([^)]*)\)", r"\1", message)
    if not isinstance(option_names, dict):
        option_names = {name: "--" + name.replace("_", "-") for name in option_names}
    for name in sorted(option_names, key=len, reverse=True):
        option = option_names[name]
        if message.startswith(f"{name} "):
            message = option + message[len(name):]
        message = re.sub(rf"\boption {re.escape(name)}\b(?!-)", f"option {option}", message)
    return message


def option_strings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """{parameter name: option string} of the (sub-)command ``args`` ran: each option's
    destination and its longest spelling (``max_sweeps`` -> ``--max-sweeps``), for
    :func:`speak_options`."""
    names: dict[str, str] = {}
    while parser is not None:
        chosen = None
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(args, action.dest, None) or "")
            elif action.option_strings and action.dest not in (argparse.SUPPRESS, "help"):
                names[action.dest] = max(action.option_strings, key=len)
        parser = chosen
    return names


def given_options(parser: argparse.ArgumentParser, argv: list[str]) -> frozenset[str]:
    """The destinations of the options written on the command line ``argv`` (a default is not
    given, an explicit value equal to the default is), found by parsing ``argv`` again with
    every default suppressed. ``parser`` is a fresh parser of the same commands; it is
    changed."""
    def suppress(p: argparse.ArgumentParser) -> None:
        p._defaults.clear()
        for action in p._actions:
            action.default = argparse.SUPPRESS
            if isinstance(action, argparse._SubParsersAction):
                for sub in set(action.choices.values()):
                    suppress(sub)

    suppress(parser)
    try:
        names = vars(parser.parse_args(argv))
    except SystemExit:  # not reached: the same argv parsed once already
        return frozenset()
    return frozenset(names)


def given(args: argparse.Namespace, name: str) -> bool:
    """Whether option ``name`` (its destination) was written on the command line (the
    ``given`` set :func:`npmrf3d.cli.main.main` records; unknown: False)."""
    return name in getattr(args, "given", frozenset())


def environment_problem() -> str | None:
    """One line about an environment setting that would make a run fail with a traceback
    (``NUMBA_NUM_THREADS`` of 0, negative or not a number, as this process started with it or as
    it is now), else None."""
    return THREAD_SETTING_PROBLEM or thread_setting_problem(os.environ.get("NUMBA_NUM_THREADS"))
