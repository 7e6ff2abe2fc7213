"""Collection rule of the whole repository: without the optional ``[neural]`` extra, the
doctests of the neural method's torch modules cannot be imported, so they are not collected
(the default ``python -m pytest`` runs with ``.[test]`` only; ``.ci/run`` installs the extra and
runs them with ``tests_neural``)."""

from __future__ import annotations

import importlib.util

TORCH_MODULES = ["npmrf3d/methods/neural/descriptor.py", "npmrf3d/methods/neural/engine.py",
                 "npmrf3d/methods/neural/generator.py", "npmrf3d/methods/neural/noise.py",
                 "npmrf3d/methods/neural/zarr_volume.py"]

collect_ignore = [] if importlib.util.find_spec("torch") is not None else TORCH_MODULES
