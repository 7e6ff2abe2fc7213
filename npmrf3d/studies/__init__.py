"""Studies: the comparisons of Urs et al. 2014 (sections V-VII) as grids of runs on Dask.

* :mod:`~npmrf3d.studies.grid`: :class:`Study`, :class:`Scale`, :class:`Method`,
  :class:`RunSpec` (a study is declared as data);
* :mod:`~npmrf3d.studies.catalog`: the seven studies, the ground-truth study and the study
  exemplars (:data:`STUDIES`);
* :mod:`~npmrf3d.studies.runner`: :func:`run_study` on a Dask cluster
  (:mod:`npmrf3d._cluster`) or serially; :mod:`~npmrf3d.studies.execute`: one run;
* :mod:`~npmrf3d.studies.groundtruth`: 2D -> 3D comparison with a real volume;
* :mod:`~npmrf3d.studies.report`: figures and the self-contained HTML report;
  the ``npmrf3d study`` and ``npmrf3d report`` commands are :mod:`npmrf3d.cli.study`.

Dask is imported only when a study runs on it.
"""

from .catalog import STUDIES, get_study
from .grid import Method, RunSpec, Scale, Study
from .runner import run_study

__all__ = ["STUDIES", "Method", "RunSpec", "Scale", "Study", "get_study", "run_study"]
