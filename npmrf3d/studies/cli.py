"""Moved: the ``study`` and ``report`` commands live in :mod:`npmrf3d.cli.study`.

Kept so that ``from npmrf3d.studies.cli import study_main`` (the one-line scripts under
``studies/`` in older checkouts) still works. Imported by nothing in the package.
"""

from ..cli.study import register, study_main

__all__ = ["register", "study_main"]
