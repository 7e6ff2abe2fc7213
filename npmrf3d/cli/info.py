"""``npmrf3d info``: what this installation has and what the machine offers."""

from __future__ import annotations

import argparse
import dataclasses
import os

from .. import __version__, data, io
from .._kernels import _jit
from ..config import COHERENT_RULE, PRESETS, SUPPORTS
from ..methods import METHODS
from ..model.exemplar import BUNDLED_PREFIX
from ..model.heuristics import HEURISTICS
from ._common import say

__all__ = ["register", "run"]


def register(commands, formatter_class) -> None:
    """Add the ``info`` sub-command."""
    parser = commands.add_parser(
        "info",
        help="print versions, threads, bundled exemplars, methods, heuristics, supports and presets",
        description="Print the version, package versions, numba threads, CPU count, bundled "
                    "exemplars, registered methods, heuristics, estimator supports and decision-rule presets.",
        formatter_class=formatter_class,
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace, argv: list[str]) -> int:
    """``npmrf3d info``: versions, threads, exemplars, methods, heuristics, supports, presets."""
    versions = io.package_versions()
    say(f"npmrf3d {__version__}")
    say(f"platform: {versions['platform']}")
    say(f"CPU count: {os.cpu_count()}")
    say(f"numba threads: {_jit.thread_count()}")
    say("packages:")
    for name, value in versions.items():
        if name not in ("platform", "cpu_count"):
            say(f"  {name:<11} {value}")
    say("bundled exemplars:")
    for name in data.available():
        mark = "  (default)" if name == data.DEFAULT_EXEMPLAR else ""
        say(f"  {BUNDLED_PREFIX}{name}{mark}")
    say("methods:")
    width = max(len(name) for name in METHODS)
    for name, method in METHODS.items():
        say(f"  {name:<{width}}  {method.description}")
    say("heuristics:")
    for h in HEURISTICS.values():
        kind = "objective" if h.objective else "no objective"
        say(f"  {h.name}  {h.description} ({kind})")
    say(f"supports: {', '.join(SUPPORTS)} (coherent: centre_bandwidth={COHERENT_RULE.centre_bandwidth} "
        f"x the exemplar's deviation, outlier={COHERENT_RULE.outlier})")
    say("presets of support full:")
    for name, rule in PRESETS.items():
        fields = ", ".join(f"{k}={v}" for k, v in dataclasses.asdict(rule).items())
        say(f"  {name:<8} {fields}")
    return 0
