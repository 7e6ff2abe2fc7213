"""Command line: ``npmrf3d synth | info | metrics | study | report | baseline kopf``.

One module per sub-command (:mod:`.synth`, :mod:`.info`, :mod:`.metrics`, :mod:`.study` with
``report``, :mod:`.baseline`), registered by the static list :data:`.main.COMMANDS`; what they
share is in :mod:`._common`. Only this package prints and draws progress bars.
"""

from ._common import PROG, say
from .main import build_parser, main

__all__ = ["PROG", "build_parser", "main", "say"]
