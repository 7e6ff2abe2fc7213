"""The one lazy import of the package: the torch side of :mod:`npmrf3d.methods.neural`.

PyTorch is an optional extra (``pip install "npmrf3d[neural]"``); ``import npmrf3d`` must work
and stay light without it. Every entry point of the neural method therefore reaches its torch
modules through :func:`engine` (and :func:`zarr_writer`), which import them on first use and
turn a missing extra into one user-facing line (:class:`MissingExtraError`, exit 2 on the
command line). ``tests/test_architecture.py`` checks that this is the only such import.
"""

from __future__ import annotations

import importlib
import importlib.util

from ...errors import ParameterError

__all__ = ["MissingExtraError", "engine", "missing", "require", "zarr_writer"]

#: The install line every "missing extra" message gives.
INSTALL = 'pip install "npmrf3d[neural]"'


class MissingExtraError(ParameterError):
    """The neural method was asked for without its optional dependencies installed."""


def require(module: str, what: str):
    """Import third-party ``module`` or raise :class:`MissingExtraError` naming ``what`` needs it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtraError(
            f"{what} needs {module}, which is not installed ({exc.msg if hasattr(exc, 'msg') else exc}); "
            f"install the neural extra: {INSTALL} (install PyTorch's CPU build first to avoid "
            f"the multi-GB CUDA build)") from None


def missing(what: str = "the neural method", modules=("torch",)) -> str | None:
    """Why ``what`` cannot run here (the first of ``modules`` that is not installed), or None;
    found without importing the modules (``import npmrf3d`` stays free of torch).

    >>> missing(modules=("os",)) is None
    True
    """
    for module in modules:
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):  # a broken or hidden module (sys.modules[name] = None)
            found = False
        if not found:
            return f"{what} needs {module}, which is not installed; install the neural extra: {INSTALL}"
    return None


def engine(what: str = "the neural method"):
    """:mod:`npmrf3d.methods.neural.engine`, importing torch first (a clear error without it)."""
    require("torch", what)
    return importlib.import_module("npmrf3d.methods.neural.engine")


def zarr_writer(what: str = "writing a Zarr volume"):
    """:mod:`npmrf3d.methods.neural.zarr_volume`, with torch and zarr (a clear error without them)."""
    require("torch", what)
    require("zarr", what)
    return importlib.import_module("npmrf3d.methods.neural.zarr_volume")
