"""Shared entry point of the study scripts: ``python studies/<name>.py [options]`` runs
``npmrf3d study <name> [options]``, also from a source checkout that is not installed."""

import pathlib
import sys

try:
    import npmrf3d  # noqa: F401
except ImportError:  # running from a source checkout that is not installed
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))


def main(name: str) -> None:
    """Run study ``name`` with the command-line options of this process and exit."""
    from npmrf3d.cli.study import study_main

    sys.exit(study_main(name))
