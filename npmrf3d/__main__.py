"""``python -m npmrf3d``: the command line of :mod:`npmrf3d.cli`."""

from npmrf3d.cli import main

raise SystemExit(main())
