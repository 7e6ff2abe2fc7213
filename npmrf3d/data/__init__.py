"""Bundled exemplar images (real photographs and micrographs, public domain / CC0).

==================  =============  ==============================================
name                shape          content (scikit-image source)
==================  =============  ==============================================
``brick``           128 x 128      brick wall (``brick``, 4x smaller)
``grass``           128 x 128      grass (``grass``, 4x smaller)
``gravel``          128 x 128      gravel (``gravel``, 4x smaller)
``gravel64``        64 x 64        top-left crop of ``gravel`` (the default)
``ihc``             128 x 128 x 3  stained tissue micrograph (``immunohistochemistry``)
``ihc64``           64 x 64 x 3    top-left crop of ``ihc``
``hubble``          128 x 128 x 3  galaxies on black (``hubble_deep_field``)
``lawn``            128 x 128      lawn from above (``camera``)
``microaneurysms``  96 x 96        retina with vessels and lesions (``microaneurysms``)
``phase_bands``     128 x 128      banded phase-image background (``cell``)
``pompeii_coins``   128 x 128      coins on a tray (``coins``)
``polymer_front``   128 x 128      micro-CT slices of short fibres in a polymer
``polymer_right``   128 x 128      matrix, one per view (the middle slices of
``polymer_top``     128 x 128      quanfima's 128^3 scan, MIT; not scikit-image)
``retina_vessels``  128 x 128 x 3  fundus photograph, vessels (``retina``)
``rocket_truss``    80 x 80 x 3    launch-tower truss (``rocket``)
``stripes``         80 x 80 x 3    flag stripes (``astronaut``)
``tabby_fur``       80 x 80 x 3    cat fur (``chelsea``)
``wood``            128 x 128 x 3  wooden table grain (``coffee``)
==================  =============  ==============================================

8-bit grey or RGB PNGs; the three ``polymer_*`` slices are the inputs of ``npmrf3d materials
--slices`` (docs/materials.md). One 3D exemplar, for the methods that take a volume
(``npmrf3d volume bundled:fibres48``):

==================  =============  ==============================================
name                shape          content (source)
==================  =============  ==============================================
``fibres48``        48 x 48 x 48   short fibres in a polymer matrix, micro-CT
                                   (the centre of quanfima's 128^3 scan, MIT)
==================  =============  ==============================================

an 8-bit grey ``.npy`` volume. Origin, licence and the exact recipe of each are in
``SOURCES.md``. Load one with ``npmrf3d.io.read_array(npmrf3d.data.path(name))``.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib.resources
import pathlib

from ..errors import ParameterError

__all__ = ["DEFAULT_EXEMPLAR", "available", "path", "volumes"]

#: Name of the exemplar used when none is given.
DEFAULT_EXEMPLAR = "gravel64"

_SUFFIX = ".png"
_VOLUME_SUFFIX = ".npy"
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
    return _names(_SUFFIX)


def volumes() -> list[str]:
    """Names of the bundled 3D exemplars (volumes), sorted: ``["fibres48"]``."""
    return _names(_VOLUME_SUFFIX)


def _names(suffix: str) -> list[str]:
    return sorted(
        entry.name.removesuffix(suffix)
        for entry in importlib.resources.files(__name__).iterdir()
        if entry.name.endswith(suffix)
    )


def path(name: str) -> pathlib.Path:
    """File of a bundled exemplar, an image or a volume.

    Parameters
    ----------
    name : str
        One of :func:`available` or :func:`volumes`.

    Returns
    -------
    pathlib.Path
        Path of the PNG (image) or ``.npy`` (volume) file (extracted to a temporary file if the
        package is zipped).

    Raises
    ------
    ParameterError
        If ``name`` is not a bundled exemplar.
    """
    names, solids = available(), volumes()
    if name not in names and name not in solids:
        raise ParameterError(
            f"exemplar name must be one of {', '.join(names)} (images) or "
            f"{', '.join(solids)} (volumes); got {name!r}"
        )
    suffix = _SUFFIX if name in names else _VOLUME_SUFFIX
    resource = importlib.resources.files(__name__).joinpath(name + suffix)
    return _EXTRACTED.enter_context(importlib.resources.as_file(resource))
