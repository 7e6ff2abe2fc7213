"""Figures of exemplars and volumes (matplotlib, object-oriented API only).

Everything here builds :class:`matplotlib.figure.Figure` objects directly: no pyplot state,
no ``show``, so it works with any backend (including Agg on a headless machine).

Slice orientation: every 2-D slice is drawn with its first array axis as rows, exactly like
the exemplar it is compared with — front ``volume[:, :, k]`` has rows i and columns j,
right ``volume[i]`` rows j and columns k, top ``volume[:, j]`` rows i and columns k.
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from matplotlib.transforms import Affine2D

from .io.files import as_volume, atomic_write

__all__ = ["plot_cube", "plot_slices", "preview_figure", "save_figure", "to_display"]

_GREY = "gray"
#: Brightness of the cube faces (front, top, side), a hint of shading for depth.
_CUBE_SHADE = (1.0, 0.9, 0.78)
#: Oblique projection of the depth axis k: angle above the horizontal and foreshortening.
_CUBE_ANGLE = math.radians(35.0)
_CUBE_DEPTH = 0.6
_PANEL_INCHES = (3.2, 4.0)


def _value_range(*arrays: np.ndarray) -> tuple[float, float]:
    """Finite minimum and maximum over ``arrays`` ((0, 1) if there are no finite values)."""
    finite = [a[np.isfinite(a)] for a in (np.asarray(x, dtype=np.float64) for x in arrays)]
    finite = [a for a in finite if a.size]
    if not finite:
        return 0.0, 1.0
    return min(float(a.min()) for a in finite), max(float(a.max()) for a in finite)


def _limits(vmin: float | None, vmax: float | None, *arrays: np.ndarray) -> tuple[float, float]:
    """``vmin`` and ``vmax``, each defaulting to the finite minimum or maximum of ``arrays``
    (read only when one is missing: a float64 copy of a large volume is not small)."""
    if vmin is not None and vmax is not None:
        return vmin, vmax
    lo, hi = _value_range(*arrays)
    return (lo if vmin is None else vmin), (hi if vmax is None else vmax)


def to_display(
    image: np.ndarray, *, vmin: float | None = None, vmax: float | None = None
) -> np.ndarray:
    """Turn an ``(H, W, C)`` image into something :meth:`Axes.imshow` can show.

    Parameters
    ----------
    image : numpy.ndarray
        Array of shape ``(H, W, C)`` (or ``(H, W)``, treated as ``C = 1``).
    vmin, vmax : float, optional
        Value range mapped to black and white for RGB images; defaults to the image range.

    Returns
    -------
    numpy.ndarray
        ``C == 3``: float ``(H, W, 3)`` RGB scaled to ``[0, 1]`` by ``vmin``/``vmax`` and
        clipped. Otherwise: the first channel, ``(H, W)``, unscaled (show it with a
        colormap and ``vmin``/``vmax``).
    """
    image = np.asarray(image)
    if image.ndim == 2:
        return image
    if image.shape[-1] != 3:
        return image[..., 0]
    lo, hi = _limits(vmin, vmax, image)
    span = hi - lo if hi > lo else 1.0
    return np.clip((image.astype(np.float32) - lo) / span, 0.0, 1.0)


def _show(ax: Axes, image: np.ndarray, vmin: float, vmax: float, **kwargs: Any) -> AxesImage:
    """imshow ``image`` (H, W, C) on ``ax``: grey colormap for one channel, RGB for three."""
    data = to_display(image, vmin=vmin, vmax=vmax)
    if data.ndim == 2:
        kwargs.update(cmap=_GREY, vmin=vmin, vmax=vmax)
    return ax.imshow(data, **kwargs)


def _rgb(image: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """Float RGB ``(H, W, 3)`` in [0, 1] of ``image`` as :func:`_show` would draw it."""
    data = to_display(image, vmin=vmin, vmax=vmax)
    if data.ndim == 3:
        return data
    return colormaps[_GREY](Normalize(vmin, vmax, clip=True)(data))[..., :3]


def _bare(ax: Axes) -> None:
    ax.set_xticks([])
    ax.set_yticks([])


def _centre_slices(volume: np.ndarray) -> list[tuple[str, np.ndarray, str, str]]:
    """``(title, slice (rows, cols, C), row axis, column axis)`` for front, right and top."""
    n1, n2, n3, _ = volume.shape
    return [
        (f"front  k={n3 // 2}", volume[:, :, n3 // 2], "i", "j"),
        (f"right  i={n1 // 2}", volume[n1 // 2], "j", "k"),
        (f"top  j={n2 // 2}", volume[:, n2 // 2], "i", "k"),
    ]


def _new_axes(count: int) -> tuple[Figure, list[Axes]]:
    fig = Figure(figsize=(_PANEL_INCHES[0] * count, _PANEL_INCHES[1]), layout="constrained")
    return fig, list(np.atleast_1d(fig.subplots(1, count)))


def plot_slices(
    volume: np.ndarray,
    *,
    axes: Sequence[Axes] | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
) -> list[AxesImage]:
    """Draw the three orthogonal centre slices of a volume.

    Parameters
    ----------
    volume : numpy.ndarray
        Array of shape ``(N1, N2, N3, C)``.
    axes : sequence of 3 Axes, optional
        Where to draw front ``volume[:, :, N3 // 2]``, right ``volume[N1 // 2]`` and top
        ``volume[:, N2 // 2]``; a new figure is made if omitted.
    vmin, vmax : float, optional
        Shared value range; defaults to the volume range.

    Returns
    -------
    list of matplotlib.image.AxesImage
        The three images (``images[0].figure`` is the figure).
    """
    volume = as_volume(volume)
    if axes is None:
        axes = _new_axes(3)[1]
    if len(axes) != 3:
        raise ValueError(f"plot_slices needs 3 axes; got {len(axes)}")
    vmin, vmax = _limits(vmin, vmax, volume)
    images = []
    for ax, (title, image, rows, cols) in zip(axes, _centre_slices(volume)):
        images.append(_show(ax, image, vmin, vmax))
        ax.set_title(title)
        ax.set_ylabel(rows, rotation=0, verticalalignment="center")
        ax.set_xlabel(cols)
        _bare(ax)
    return images


def plot_cube(
    volume: np.ndarray,
    *,
    ax: Axes | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
) -> list[AxesImage]:
    """Draw the volume as a cube in oblique projection, showing its three visible faces.

    The front face is ``volume[:, :, 0]`` drawn like the front slice (i down, j right);
    the depth axis k recedes up and to the right, so the top face is ``volume[0]`` (the
    plane i = 0) and the side face is ``volume[:, -1]`` (the plane j = N2 - 1). Each face is
    an image placed with an affine transform; edges and axis names are drawn on top.

    Parameters
    ----------
    volume : numpy.ndarray
        Array of shape ``(N1, N2, N3, C)``.
    ax : matplotlib.axes.Axes, optional
        2-D axes to draw on; a new figure is made if omitted.
    vmin, vmax : float, optional
        Shared value range; defaults to the volume range.

    Returns
    -------
    list of matplotlib.image.AxesImage
        The front, top and side face images.
    """
    volume = as_volume(volume)
    if ax is None:
        ax = _new_axes(1)[1][0]
    vmin, vmax = _limits(vmin, vmax, volume)
    n1, n2, n3, _ = volume.shape
    scale = max(n1, n2, n3)
    height, width = n1 / scale, n2 / scale  # front face: rows i (down), columns j (right)
    depth = _CUBE_DEPTH * n3 / scale
    dx, dy = depth * math.cos(_CUBE_ANGLE), depth * math.sin(_CUBE_ANGLE)

    # Each face is drawn on the unit square (u = column fraction, v = 1 - row fraction)
    # and mapped to the screen by [[a, c, e], [b, d, f]]: x = a u + c v + e, y = b u + d v + f.
    faces = [
        (volume[:, :, 0], (width, 0.0, 0.0, height, 0.0, 0.0)),  # rows i, columns j
        (volume[0], (dx, dy, -width, 0.0, width, height)),  # rows j, columns k
        (volume[:, -1], (dx, dy, 0.0, height, width, 0.0)),  # rows i, columns k
    ]
    images = []
    for (face, matrix), shade in zip(faces, _CUBE_SHADE):
        transform = Affine2D.from_values(*matrix) + ax.transData
        images.append(
            ax.imshow(
                _rgb(face, vmin, vmax) * shade,
                extent=(0.0, 1.0, 0.0, 1.0),
                transform=transform,
                interpolation="nearest",
            )
        )

    corners = {
        "front": [(0, 0), (width, 0), (width, height), (0, height), (0, 0)],
        "top": [(0, height), (dx, height + dy), (width + dx, height + dy), (width, height)],
        "side": [(width, 0), (width + dx, dy), (width + dx, height + dy)],
    }
    for line in corners.values():
        ax.plot(*zip(*line), color="black", linewidth=0.8)
    pad = 0.06
    ax.text(-pad, height / 2, "i", ha="right", va="center")
    ax.text(width / 2, -pad, "j", ha="center", va="top")
    ax.text(width + dx / 2 + pad, dy / 2 - pad, "k", ha="left", va="top")
    ax.set_xlim(-3 * pad, width + dx + pad)
    ax.set_ylim(-3 * pad, height + dy + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(f"cube: front k=0, top i=0, side j={n2 - 1}", fontsize="medium")
    return images


def _distinct_exemplars(
    exemplars: Mapping[str, np.ndarray],
) -> list[tuple[list[str], np.ndarray]]:
    """Group views that share the same exemplar (same object or equal content)."""
    groups: list[tuple[list[str], np.ndarray]] = []
    for view, exemplar in exemplars.items():
        array = np.asarray(exemplar)
        for views, seen in groups:
            if array is seen or (array.shape == seen.shape and np.array_equal(array, seen)):
                views.append(view)
                break
        else:
            groups.append(([view], array))
    return groups


def preview_figure(
    volume: np.ndarray,
    exemplars: Mapping[str, np.ndarray],
    *,
    title: str | None = None,
) -> Figure:
    """One-row overview: exemplar(s), the three centre slices and the cube.

    Parameters
    ----------
    volume : numpy.ndarray
        Array of shape ``(N1, N2, N3, C)``.
    exemplars : Mapping[str, numpy.ndarray]
        View name -> exemplar ``(H, W, C)``; one panel per distinct exemplar, labelled with
        its views. All panels share the value range of the exemplars (of the volume if
        there are none), so slices and exemplars are directly comparable.
    title : str, optional
        Figure title; the volume shape is always appended.

    Returns
    -------
    matplotlib.figure.Figure
        About 16 x 4 inches for one exemplar, dpi 100. For ``C`` other than 1 or 3 only
        channel 0 is shown, with a colour bar.
    """
    volume = as_volume(volume)
    groups = _distinct_exemplars(exemplars)
    vmin, vmax = _value_range(*(array for _, array in groups)) if groups else _value_range(volume)

    fig, axes = _new_axes(len(groups) + 4)
    fig.set_dpi(100)
    for ax, (views, exemplar) in zip(axes, groups):
        _show(ax, exemplar, vmin, vmax)
        ax.set_title(f"exemplar ({', '.join(views)})")
        ax.set_xlabel(" × ".join(str(n) for n in exemplar.shape[:2]))
        _bare(ax)
    slices = plot_slices(volume, axes=axes[len(groups) : -1], vmin=vmin, vmax=vmax)
    plot_cube(volume, ax=axes[-1], vmin=vmin, vmax=vmax)

    n1, n2, n3, channels = volume.shape
    if channels not in (1, 3):
        fig.colorbar(slices[0], ax=axes, shrink=0.8, label=f"channel 0 of {channels}")
    shape = f"volume {n1} × {n2} × {n3}, C = {channels}"
    fig.suptitle(f"{title} — {shape}" if title else shape)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike[str]) -> pathlib.Path:
    """Save ``fig`` atomically; the format follows the extension (PNG if there is none).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = pathlib.Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt))
