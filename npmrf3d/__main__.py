"""``python -m npmrf3d``: the command line of :mod:`npmrf3d.cli`."""

from .cli import main

raise SystemExit(main())
