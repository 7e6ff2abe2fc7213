"""Bundled exemplar images (real photographs and micrographs, public domain / CC0).

=============  ==========  ================================================
name           shape       content
=============  ==========  ================================================
``brick``      128 x 128   brick wall (``skimage.data.brick``, 4x smaller)
``grass``      128 x 128   grass (``skimage.data.grass``, 4x smaller)
``gravel``     128 x 128   gravel (``skimage.data.gravel``, 4x smaller)
``gravel64``   64 x 64     top-left 64 x 64 crop of ``gravel``
``ihc``        128 x 128   colour tissue micrograph (``skimage.data.immunohistochemistry``, 4x smaller)
``ihc64``      64 x 64     top-left 64 x 64 crop of ``ihc`` (colour)
=============  ==========  ================================================

``ihc`` and ``ihc64`` are 8-bit RGB, the others 8-bit grey PNGs; origin, licence and recipe are in ``SOURCES.md`` next to them.
Load one with ``npmrf3d.io.read_array(npmrf3d.data.path(name))``.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib.resources
import pathlib

from npmrf3d.errors import ParameterError

__all__ = ["DEFAULT_EXEMPLAR", "available", "path"]

#: Name of the exemplar used when none is given.
DEFAULT_EXEMPLAR = "gravel64"

_SUFFIX = ".png"
# Keeps files extracted from a zipped install alive until the interpreter exits.
_EXTRACTED = contextlib.ExitStack()
atexit.register(_EXTRACTED.close)


def available() -> list[str]:
    """Names of the bundled exemplars, sorted.

    Returns
    -------
    list of str
        E.g. ``["brick", "grass", "gravel", "gravel64"]``.
    """
    return sorted(
        entry.name.removesuffix(_SUFFIX)
        for entry in importlib.resources.files(__name__).iterdir()
        if entry.name.endswith(_SUFFIX)
    )


def path(name: str) -> pathlib.Path:
    """File of a bundled exemplar.

    Parameters
    ----------
    name : str
        One of :func:`available`.

    Returns
    -------
    pathlib.Path
        Path of the PNG file (extracted to a temporary file if the package is zipped).

    Raises
    ------
    ParameterError
        If ``name`` is not a bundled exemplar.
    """
    names = available()
    if name not in names:
        raise ParameterError(
            f"exemplar name must be one of {', '.join(names)}; got {name!r}"
        )
    resource = importlib.resources.files(__name__).joinpath(name + _SUFFIX)
    return _EXTRACTED.enter_context(importlib.resources.as_file(resource))
