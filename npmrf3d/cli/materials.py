"""``npmrf3d materials``: from a segmented (or grey, thresholded) slice, three slices or a 3D crop
to a label volume and a materials report: does the volume keep what the input shows?

The input's phases: a grey image or volume with at most
:data:`npmrf3d.methods.npmrf_coherent.SEGMENTED_MAX_VALUES` distinct values is a label image
(its values are the phases, kept as they are); one with more is split at Otsu's threshold (or
``--threshold``) into 0 and 1 (uint8). A colour image is refused (its channels differ; a phase
is not a colour's grey level), as is an image with one phase. The method sees the phases as
0, 1, ..., n - 1 in the order of their values; the volume maps them back, so ``volume.npy``
holds the input's values in the input's dtype (``(N1, N2, N3, 1)``; ``volume.tif`` the same
values as float32).

A grey slice split into two phases is split before synthesis (the method copies the phases,
with the segmented preset) or after it (the method copies the grey values with ``synth``'s
default, and the volume is split at the same threshold): ``--split auto`` splits after when the
input's minority phase is under :data:`SPLIT_AFTER_BELOW` of its pixels (:func:`split_order`).

A 2D input runs ``synth``'s method (``npmrf``, every option of ``synth``); a 3D crop runs
``volume-lh`` (the method that copies the crop's own 3D neighbourhoods, whose connectivity no
slice shows) with its defaults, ``--levels`` and ``--size``. The report
(:mod:`npmrf3d.analysis.materials_compare`, figures by :mod:`._materials_figures`) goes into the
run folder beside the usual files.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import pathlib
import time

import numpy as np

from ..analysis.materials import DIFFUSIVITY_SOLVERS
from ..analysis.materials_compare import materials_report
from ..config import SynthesisConfig
from ..errors import ParameterError
from ..io.files import read_stack, write_json, write_npy
from ..io.runs import RUN_FILES
from ..methods import check_resources, get_method
from ..methods._api import settled
from ..methods.npmrf_coherent import SEGMENTED_MAX_VALUES
from ..model.exemplar import exemplar_source, resolve_exemplars
from ..model.exemplar3d import MIN_VOLUME_SIDE, interpret, load_volume_exemplar, volume_fits
from ..model.neighbourhood import VIEWS
from ..model.otsu import otsu_threshold
from ._blocks import blockwise_requested, zarr_output
from ._common import check_checkpoint, claim_output, dry_run, output_folder, parse_size, say, write_result
from ._generic import add_method_parser, config_options, method_options, refuse_written
from ._materials_figures import FIGURES, write_figures, write_page
from ._options import given
from ._progress import run_method

__all__ = ["MATERIALS_FILES", "SPLIT_AFTER_BELOW", "phase_indices", "read_input", "register", "segment",
           "split_order"]

METHOD = get_method("npmrf")
CROP_METHOD = get_method("volume-lh")
#: What the command writes beside the run files.
MATERIALS_FILES = ("materials.json", "materials.html", *FIGURES)
#: ``--exemplar-kind``: a 3-D array is guessed, an image or a 3D crop.
EXEMPLAR_KINDS = ("auto", "image", "volume")
#: ``--split``: when a grey slice is split into two phases, before or after synthesis.
SPLIT_ORDERS = ("auto", "before", "after")
#: ``--split auto`` splits a grey slice after synthesis when its minority phase (after the split)
#: is under this share of its pixels, else before. Measured with the materials benchmark (64^3,
#: seeds 7/8/9, cells of 13 inside the real crops' spread; docs/materials.md, "Grey slices: split
#: before or after synthesis"): splitting after kept more on the five grey scans whose minority
#: phase is 0.08-0.18 (two bone cores, the polymer, the FiberForm, the weave: 129 against 74 cells
#: of 195), splitting before on the soil (0.44: 36 against 30 of 39) and on the bundled phase_bands
#: (0.49, 32^3, seed 0: 8 against 4 of its report's 10 judged verdicts); the cut lies between.
#: Held out of that choice: splitting after kept 31 against 29 cells of 39 on cement voids (0.20)
#: and 34 against 31 on a tubular tissue (0.30), splitting before 30 against 29 on a bone (0.31).
SPLIT_AFTER_BELOW = 0.3


def _extra(parser: argparse.ArgumentParser, sections: dict) -> None:
    group = parser.add_argument_group("materials")
    group.add_argument("--threshold", default="auto", metavar="auto|VALUE",
                       help=f"auto: an input with at most {SEGMENTED_MAX_VALUES} values keeps them as "
                            f"phases, one with more is split at Otsu's threshold; VALUE: phase 1 = "
                            f"values above it, phase 0 the rest")
    group.add_argument("--split", default="auto", choices=SPLIT_ORDERS, metavar="{" + ",".join(SPLIT_ORDERS) + "}",
                       help=f"a grey slice split into two phases: before synthesis (the method copies the "
                            f"phases), after it (the method copies the grey values; the volume is split at "
                            f"the same threshold), or auto: after when the minority phase is under "
                            f"{SPLIT_AFTER_BELOW:.0%} of the slice, else before (a 3D crop: before)")
    group.add_argument("--slices", default=None, metavar="FRONT,RIGHT,TOP",
                       help="three slices, one per view (front: axes 0,1; right: 1,2; top: 0,2), "
                            "instead of INPUT, for an anisotropic material (default: none)")
    group.add_argument("--diffusivity", default="finite-volume", choices=DIFFUSIVITY_SOLVERS,
                       metavar="{" + ",".join(DIFFUSIVITY_SOLVERS) + "}",
                       help="the relative-diffusivity solver: a finite-volume solve (scipy), or "
                            "TauFactor (the [materials] extra; the same numbers, slower on a CPU)")


def register(commands, formatter_class) -> None:
    """Add the ``materials`` sub-command."""
    parser = add_method_parser(
        commands, "materials", METHOD,
        help="a label volume from a segmented slice, three slices or a 3D crop, and a materials report",
        description=(
            "Make a label volume from a segmented (or grey, thresholded) slice, three slices\n"
            "or a small 3D crop, and report per phase whether it keeps what the input shows:\n"
            "volume fraction, surface per volume, two-point correlation, chord lengths,\n"
            f"percolation, relative diffusivity. Writes {', '.join(RUN_FILES)},\n"
            "materials.json, materials.html and its figures (docs/materials.md).\n\n"
            "examples:\n"
            "  npmrf3d materials bundled:phase_bands --size 32 --out bands\n"
            "  npmrf3d materials slice.png --threshold 120 --out rock\n"
            "  npmrf3d materials --slices front.png,right.png,top.png --out fibres\n"
            "  npmrf3d materials bundled:fibres48 --size 32 --out crop   # a 3D crop: volume-lh"
        ),
        out="npmrf3d-materials-out", formatter_class=formatter_class, handler=run, extra=_extra, zarr=False)
    hidden = {f"exemplar_{v}" for v in VIEWS} | {"block", "workers", "scheduler"}  # refused here
    for action in parser._actions:
        if action.dest == "exemplar":
            action.metavar = "INPUT"
            action.help = ("2D slice (image or .npy), 3D crop (.npy or TIFF stack) or bundled:NAME "
                           "(default: %(default)s)")
        elif action.dest == "exemplar_kind":
            action.choices = EXEMPLAR_KINDS
            action.metavar = "{" + ",".join(EXEMPLAR_KINDS) + "}"
            action.help = ("auto reads a 3-D array recognised as a volume as a 3D crop; image reads it as an "
                           "image; volume reads it as a 3D crop")
        elif action.dest in hidden:
            action.help = argparse.SUPPRESS
    parser.usage = "%(prog)s [INPUT] [options]"
    parser.epilog = f"Writes {', '.join(RUN_FILES + MATERIALS_FILES)} into the output folder."


def _fail(message: str):
    raise ParameterError(message)


def read_input(source, name: str, exemplar_kind: str = "auto") -> np.ndarray:
    """One input as stored: a grey 2D ``(H, W)`` or 3D ``(D, H, W)`` array (a colour image
    whose channels are all equal is grey; other colour images are refused)."""
    if isinstance(source, np.ndarray):
        array, axes = source, None
    else:
        array, info = read_stack(source, what="input file")
        axes = info["axes"]
        if info.get("alpha"):
            if np.any(array[..., -1] != array[..., -1].max()):
                _fail(f"{name} has transparent pixels; save it without an alpha channel")
            array = array[..., :-1]
    if axes is None and array.ndim == 3 and exemplar_kind != "image" and 1 in array.shape[:2]:
        _fail(f"{name} of shape {array.shape} is a 3D crop one voxel thick: a crop needs at least "
              f"{MIN_VOLUME_SIDE} voxels along every side (a single slice goes in as a 2D image)")
    kind, shaped = interpret(array, axes=axes, kind=exemplar_kind, name=name, expect="volume")
    if shaped.shape[-1] > 1 and np.any(shaped != shaped[..., :1]):
        _fail(f"{name} is a colour image ({shaped.shape[-1]} channels that differ); a phase is not a "
              f"colour: give a grey slice or a label image (one value per phase)")
    grey = shaped[..., 0]
    if grey.dtype == bool or not np.issubdtype(grey.dtype, np.number) or np.iscomplexobj(grey):
        grey = grey.astype(np.uint8) if grey.dtype == bool else _fail(f"{name} must hold real numbers")
    if not np.all(np.isfinite(grey)):
        _fail(f"{name} holds NaN or infinite values")
    if kind == "volume" and min(grey.shape) < MIN_VOLUME_SIDE:
        _fail(f"{name} is a 3D input of {'x'.join(map(str, grey.shape))} voxels, too small: every side "
              f"needs at least {MIN_VOLUME_SIDE}")
    return grey


def segment(arrays: list, threshold: str = "auto") -> tuple[list, np.ndarray, str]:
    """(label arrays, the phases' values in order, how they were found) of the inputs, pooled:
    at most :data:`SEGMENTED_MAX_VALUES` values kept as phases, else Otsu's split (or
    ``threshold``) into uint8 0 and 1."""
    pooled = np.concatenate([a.ravel() for a in arrays])
    values = np.unique(pooled)
    if threshold == "auto" and len(values) <= SEGMENTED_MAX_VALUES:
        how = f"labels kept: {len(values)} values"
    else:
        if threshold == "auto":
            cut = otsu_threshold(pooled)
            how = f"grey values split at Otsu's threshold {cut:.6g}"
        else:
            try:
                cut = float(threshold)
            except ValueError:
                cut = math.nan
            if not math.isfinite(cut):
                _fail(f"--threshold must be auto or a number; got {threshold!r}")
            low, high = float(pooled.min()), float(pooled.max())
            if not low <= cut < high:
                _fail(f"--threshold {threshold} is outside the input's values [{low:.6g}, {high:.6g}): "
                      f"one phase would be empty")
            how = f"grey values split at {cut:.6g}"
        arrays = [(a > cut).astype(np.uint8) for a in arrays]
        values = np.unique(np.concatenate([a.ravel() for a in arrays]))
    if len(values) < 2:
        _fail(f"the input holds one phase only (value {values[0]}); a materials report needs two or more")
    return arrays, values, how


def split_order(labels: list, split: bool, requested: str = "auto", *, crop: bool = False) -> tuple[str, str]:
    """(``"before"`` or ``"after"``, why) the inputs' grey values are split into phases relative
    to synthesis; ``labels``: the split arrays (pooled), ``split``: whether :func:`segment` split
    grey values (a label image's phases are synthesised as they are: ``"before"``)."""
    if not split:
        if requested != "auto":
            _fail(f"--split {requested} applies to a grey input split into two phases; this input's "
                  f"values are kept as phases (a label image)")
        return "before", "a label image: the method copies its phases"
    if crop:
        if requested == "after":
            _fail("--split after applies to a slice; a 3D crop is split before volume-lh copies its phases")
        return "before", "a 3D crop: split before volume-lh copies its phases"
    share = float(np.mean(np.concatenate([a.ravel() for a in labels])))
    minority = min(share, 1.0 - share)
    if requested != "auto":
        return requested, f"--split {requested} (minority phase {minority:.3f} of the input)"
    if minority < SPLIT_AFTER_BELOW:
        return "after", (f"minority phase {minority:.3f} of the input, under {SPLIT_AFTER_BELOW}: the grey "
                         f"values synthesised, the volume split")
    return "before", (f"minority phase {minority:.3f} of the input, at least {SPLIT_AFTER_BELOW}: the phases "
                      f"synthesised")


def phase_indices(labels: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The phase numbers 0..n-1 of a label array, float32 with a channel axis (the method's input)."""
    return np.searchsorted(values, labels).astype(np.float32)[..., None]


def _inputs(args: argparse.Namespace) -> tuple[dict, dict]:
    """({view or "volume": grey array}, {view or "volume": name for run.json})."""
    views_given = [v for v in VIEWS if getattr(args, f"exemplar_{v}") is not None]
    if views_given:
        _fail(f"--exemplar-{views_given[0]} is not used by materials: give three slices with --slices")
    if args.slices is None:
        source, name = exemplar_source(args.exemplar)
        grey = read_input(source, f"input '{name}'", args.exemplar_kind)
        return ({"volume": grey} if grey.ndim == 3 else {v: grey for v in args.views.split(",")}), {"input": name}
    if given(args, "exemplar"):
        _fail("give INPUT or --slices, not both")
    parts = [p.strip() for p in args.slices.split(",")]
    if len(parts) != 3 or not all(parts):
        _fail(f"--slices must name three slices FRONT,RIGHT,TOP; got {args.slices!r}")
    if given(args, "views"):
        _fail("--views does not apply to --slices, which constrains the three views")
    if args.exemplar_kind == "volume":
        _fail("--exemplar-kind volume does not apply to --slices, which takes three 2D slices")
    arrays, names = {}, {}
    for view, text in zip(VIEWS, parts):
        source, names[view] = exemplar_source(text)
        arrays[view] = read_input(source, f"{view} slice '{names[view]}'", args.exemplar_kind)
        if arrays[view].ndim != 2:
            _fail(f"{view} slice '{names[view]}' is a volume; --slices takes three 2D slices")
    args.views = ",".join(VIEWS)
    return arrays, names


def _each_slice_shows_phases(labels: dict, sources: dict, phases: int) -> None:
    """Refuse one of three slices that holds one phase only: a material whose phases fill its
    volume shows two or more in every slice, and no volume matches slices that say otherwise."""
    for view, a in labels.items():
        first = a.flat[0]
        if view in sources and np.all(a == first):
            _fail(f"{view} slice '{sources[view]}' holds one phase only (value {first}) while the slices "
                  f"together hold {phases}; each slice must show two or more phases")


def _crop_config(args: argparse.Namespace):
    """``volume-lh``'s configuration for a 3D crop: ``--size``, ``--seed`` and ``--levels``; any
    other method option is refused (they are ``npmrf``'s)."""
    for name in method_options(SynthesisConfig):
        if name != "levels" and given(args, name):
            _fail(f"--{name.replace('_', '-')} is an option of the 2D method; a 3D crop runs volume-lh "
                  f"with its defaults (--size, --levels and --seed apply)")
    levels = {"levels": args.levels} if given(args, "levels") else {}
    return CROP_METHOD.make_config(size=parse_size(args.size), seed=args.seed, **levels)


def run(args: argparse.Namespace, argv: list[str]) -> int:
    """``npmrf3d materials``: check everything, run the method, write the run folder and report."""
    t_start = time.perf_counter()
    if zarr_output(args):
        _fail("materials writes a run folder with its report; --out must not end in .zarr")
    raw, sources = _inputs(args)
    distinct = {id(a): a for a in raw.values()}  # one slice for every view: segmented once
    segmented, values, how = segment(list(distinct.values()), args.threshold)
    by_id = dict(zip(distinct, segmented))
    labels = {k: by_id[id(a)] for k, a in raw.items()}
    _each_slice_shows_phases(labels, sources, len(values))
    crop = list(raw) == ["volume"]
    grey_split = not how.startswith("labels kept")  # segment() split grey values into two phases
    order, why = split_order(segmented, grey_split, args.split, crop=crop)
    if crop:
        method, config = CROP_METHOD, _crop_config(args)
        per_view = {"volume": load_volume_exemplar(phase_indices(labels["volume"], values), exemplar_kind="volume")}
        volume_fits(per_view["volume"], window=config.window, name=f"input '{sources['input']}'")
    else:
        method = METHOD
        config = METHOD.make_config(size=parse_size(args.size), views=args.views, seed=args.seed,
                                    **{**config_options(args, SynthesisConfig),
                                       "blockwise": blockwise_requested(args)})
        refuse_written(args, config)
        given_views = raw if order == "after" else labels  # grey values, or the phases 0..n-1
        shared = {id(a): a if order == "after" else phase_indices(a, values) for a in given_views.values()}
        per_view = resolve_exemplars(None, {v: shared[id(a)] for v, a in given_views.items()}, config.views,
                                     **method.fit(config))
        config = settled(method, config, per_view)
    out = output_folder(args, RUN_FILES + MATERIALS_FILES)
    checkpoint = None if args.checkpoint is None else pathlib.Path(args.checkpoint)
    check_checkpoint(checkpoint, out)
    if args.dry_run:
        return dry_run(method, config, per_view)
    check_resources(method, config, per_view, hint="lower --size; --dry-run shows the estimate")
    if not args.quiet and grey_split:
        say(f"{how}, {order} synthesis: {why}", error=True)
    with claim_output(out, args.overwrite):
        result = run_method(args, method, config, per_view, checkpoint=checkpoint, t_start=t_start,
                            unit="pass" if crop else "sweep")
        if order == "after":  # phase 1: above every grey value of the input's phase 0, as the method reads them
            below = max(float(per_view[v][..., 0][labels[v] == 0].max()) for v in per_view if np.any(labels[v] == 0))
            phases = (result.volume[..., 0] > below).astype(np.int64)
        else:
            phases = np.rint(result.volume[..., 0]).astype(np.int64)
        if phases.min() < 0 or phases.max() >= len(values):
            _fail("the method returned values that are not the input's phases")  # never expected
        volume = values[phases]
        if not args.quiet:
            say(f"measuring {len(values)} phases (diffusivity: {args.diffusivity})", error=True)
        report = materials_report(volume, values.tolist(), inputs=labels, diffusivity=args.diffusivity)
        report = {"input": {"kind": "crop" if crop else ("slices" if args.slices else "slice"),
                            "sources": sources, "dtype": str(values.dtype), "values": values.tolist(),
                            "phases": how, "split": order, "split_why": why},
                  "method": method.name, "diffusivity_solver": args.diffusivity, **report}
        title = f"npmrf3d materials: {method.name}, {len(values)} phases, seed {config.seed}"
        shown = {"input slice" if crop else v: (a[a.shape[0] // 2] if crop else a).astype(np.float32)[..., None]
                 for v, a in labels.items()}
        written = dataclasses.replace(result, volume=volume.astype(np.float32)[..., None],
                                      labels=values.astype(np.float32).reshape(-1, 1))  # the phases, not grey levels
        write_result(out, args, argv, "materials", written, shown, sources, title, method=method.name,
            labels=len(values), split={"order": order, "why": why})
        write_npy(out / "volume.npy", volume[..., None])
        write_figures(out, report, volume, labels)
        write_json(out / "materials.json", report)
        write_page(out, report, title)
    if not args.quiet:
        for line in report["summary"][:1]:
            say(line)
        say(f"report: {out / 'materials.html'}")
    return 0
