"""Collection rule of the whole repository: without the optional ``[neural]`` extra, the
doctests of the neural method's torch modules cannot be imported, so they are not collected
(the default ``python -m pytest`` runs with ``.[test]`` only; ``.ci/run`` installs the extra and
runs them with ``tests_neural``)."""

from __future__ import annotations

import importlib.util
import pathlib
import re

#: The neural method's modules that import torch, found by reading them (so a new one is never
#: forgotten here).
TORCH_MODULES = sorted(
    str(path.relative_to(pathlib.Path(__file__).parent))
    for path in (pathlib.Path(__file__).parent / "npmrf3d" / "methods" / "neural").glob("*.py")
    if re.search(r"^(import torch|from torch\b)", path.read_text(encoding="utf-8"), flags=re.M))

collect_ignore = [] if importlib.util.find_spec("torch") is not None else TORCH_MODULES
