"""Reading and writing exemplars, volumes, run folders and checkpoints (the public face).

Everything ``npmrf3d.io`` has always offered, from the three modules that implement it:
:mod:`npmrf3d.io.files` (arrays, volumes, TIFF stacks, JSON, versions; no package imports),
:mod:`npmrf3d.io.checkpoints` (checkpoint files and the identity of a run) and
:mod:`npmrf3d.io.runs` (run folders, which need :mod:`npmrf3d.plotting` for the preview).
Library modules import those directly; this module imports them and nothing imports it back,
so the arrows run one way.

Conventions
-----------
* An exemplar is a float32 array of shape ``(H, W, C)``; :func:`read_array` returns the
  stored array unchanged (any dtype, 2-D or 3-D) and leaves the conversion to the caller.
* A volume is a float32 array of shape ``(N1, N2, N3, C)`` indexed ``volume[i, j, k, c]``.
* Every file is written atomically, and a run folder is staged completely before it is
  moved into place (:func:`write_run`).
"""

from .checkpoints import load_checkpoint, save_checkpoint
from .files import *  # noqa: F403 (the public file functions, listed in files.__all__)
from .files import __all__ as _FILES
from .runs import RUN_FILES, run_record, write_run

__all__ = [*_FILES, "RUN_FILES", "load_checkpoint", "run_record", "save_checkpoint", "write_run"]
