"""Studies declared as data: a :class:`Study` is a grid of runs, a :class:`RunSpec` is one run.

A study crosses exemplars x methods x seeds x sizes. It has two variants, ``quick`` (tiny,
run by the tests) and ``full`` (the real comparison), each a :class:`Scale` that states its
exemplars, seeds, sizes, pyramid levels, an optional exemplar crop and, when the quick
variant needs smaller settings than the full one (e.g. windows 3/5 instead of 9/11), its own
list of methods. Nothing is code: :mod:`npmrf3d.studies.catalog` only declares values.

Parameters reach the algorithms like this:

Registered methods (:data:`npmrf3d.methods.METHODS`) are called through their ``synthesize``:

* ``npmrf`` methods call :func:`npmrf3d.synthesize` with ``study.common``, then
  ``scale.common`` (each only where the method's support and relaxation use it,
  :func:`npmrf3d.methods.npmrf_options.applies`), then the method's own ``params`` (later ones
  win) plus ``size``,
  ``levels`` and ``rng=seed``; keyword arguments are passed through unchanged, so settings of
  newer samplers (``relaxation="anneal"``, ``proposals``, ``schedule``, ``t0``, ``t_end``,
  ``sampler``) need nothing here.
* ``kopf`` methods call :func:`npmrf3d.methods.kopf.kopf_synthesize` with only the
  method's ``params`` plus ``size``, ``levels``, ``views`` and ``rng``.
* ``control`` is the structureless control: voxels drawn independently from the exemplar.
* ``real`` (ground-truth study only) is a crop of the real volume itself: the floor.
* ``neural`` (and any method with an ``unavailable`` hook) needs an optional extra: where it is
  not installed, :func:`npmrf3d.studies.runner.run_study` leaves its runs out and says so (on
  the console and under ``left_out`` in ``study.json``). Only methods with pyramid levels get
  ``levels``.

Examples
--------
>>> study = Study(
...     name="demo", title="Demo", question="Does it run?",
...     methods=(Method("H2b", params=(("heuristic", "ML_H2b"),)), Method("control", "control")),
...     full=Scale(exemplars=("gravel64",), seeds=(0, 1), sizes=(32,), levels=2),
...     quick=Scale(exemplars=("gravel64",), seeds=(0,), sizes=(8,), levels=1, crop=32),
... )
>>> [run.run_id for run in study.runs("quick")]
['gravel64-H2b-s0', 'gravel64-control-s0']
>>> study.runs("full")[1].kwargs()["rng"]
1
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, replace
from typing import Any

from ..errors import ParameterError
from ..methods import ALIASES, METHODS
from ..methods.npmrf_options import applies, combination
from ..model.neighbourhood import VIEWS

__all__ = ["ALGORITHMS", "MODES", "Method", "RunSpec", "Scale", "Study", "run_id"]

#: The study-only algorithms: they make no volume from an exemplar, so they are not methods of
#: :data:`npmrf3d.methods.METHODS`.
STUDY_ONLY = ("control", "real")
#: What a method can be: every registered method (see :data:`npmrf3d.methods.METHODS`), then
#: the study-only ones.
ALGORITHMS = (*METHODS, *STUDY_ONLY)
#: The two variants every study declares.
MODES = ("quick", "full")

Params = tuple[tuple[str, Any], ...]


def _params(value) -> Params:
    """Mapping or pairs -> a sorted tuple of (name, value) pairs (hashable, frozen)."""
    items = value.items() if isinstance(value, dict) else value
    return tuple(sorted((str(k), v) for k, v in items))


@dataclass(frozen=True)
class Method:
    """One column of a study: an algorithm with fixed parameters.

    Attributes
    ----------
    name : str
        Short label used in run ids, tables and figures (letters, digits, ``-``, ``_``, ``.``).
    algorithm : a name of :data:`npmrf3d.methods.METHODS` (or an alias), "control" or "real"
    params : tuple of (name, value) pairs
        Keyword arguments for the algorithm (a dict is accepted and frozen).
    max_seeds : int or None
        Run only the first ``max_seeds`` of the variant's seeds (None: all of them); for the
        costly rows of a study whose spread over seeds the other rows already show.
    """

    name: str
    algorithm: str = "npmrf"
    params: Params = ()
    max_seeds: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "params", _params(self.params))
        if self.algorithm in ALIASES:
            object.__setattr__(self, "algorithm", ALIASES[self.algorithm])
        if self.algorithm not in ALGORITHMS:
            raise ParameterError(f"method {self.name!r}: algorithm must be one of "
                                 f"{', '.join(ALGORITHMS)}; got {self.algorithm!r}")
        if self.max_seeds is not None and (not isinstance(self.max_seeds, int) or self.max_seeds < 1):
            raise ParameterError(f"method {self.name!r}: max_seeds must be a positive integer or "
                                 f"None; got {self.max_seeds!r}")
        if not re.fullmatch(r"[A-Za-z0-9_.+-]+", self.name):
            raise ParameterError(f"method name must use letters, digits, '_', '.', '+', '-'; "
                                 f"got {self.name!r}")


@dataclass(frozen=True)
class Scale:
    """The ``quick`` or ``full`` variant of a study.

    Attributes
    ----------
    exemplars : tuple of str
        Exemplar names (see :func:`npmrf3d.studies.catalog.load_exemplar`).
    seeds : tuple of int
    sizes : tuple of int
        Volume sides (cubes).
    levels : int
        Pyramid levels of every ``npmrf`` and ``kopf`` run.
    crop : int or None
        Use only the top-left ``crop x crop`` pixels of each exemplar (quick runs).
    common : tuple of (name, value) pairs
        Extra ``npmrf`` keyword arguments for this variant (e.g. ``max_sweeps``).
    methods : tuple of Method or None
        Replaces the study's methods in this variant (None: the study's).
    """

    exemplars: tuple[str, ...]
    seeds: tuple[int, ...] = (0,)
    sizes: tuple[int, ...] = (32,)
    levels: int = 2
    crop: int | None = None
    common: Params = ()
    methods: tuple[Method, ...] | None = None

    def __post_init__(self):
        object.__setattr__(self, "common", _params(self.common))
        object.__setattr__(self, "exemplars", tuple(self.exemplars))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        object.__setattr__(self, "sizes", tuple(int(s) for s in self.sizes))


@dataclass(frozen=True)
class RunSpec:
    """Everything one run needs; picklable, so it travels to Dask workers as is.

    ``reference`` is the path of a real volume (ground-truth study) or None; ``slice_axis`` and
    ``slice_index`` then say which of its slices is the exemplar of every view, or ``slices = 3``
    gives each view its own middle slice (:func:`npmrf3d.studies.groundtruth.exemplar_slices`).
    """

    study: str
    run_id: str
    exemplar: str
    method: str
    algorithm: str
    seed: int
    size: int
    levels: int
    params: Params = ()
    crop: int | None = None
    reference: str | None = None
    slice_axis: int = 0
    slice_index: int | None = None
    slices: int = 1

    def kwargs(self) -> dict[str, Any]:
        """Keyword arguments for the algorithm (without the exemplar and progress)."""
        out = dict(self.params)
        if self.algorithm in METHODS:
            out.update(size=self.size, rng=self.seed)
            if "levels" in METHODS[self.algorithm].config_class.__dataclass_fields__:
                out["levels"] = self.levels  # the neural method has no pyramid
        return out

    def unavailable(self) -> str | None:
        """Why this run's method cannot run here (its optional extra is missing), or None."""
        method = METHODS.get(self.algorithm)
        check = None if method is None else method.unavailable
        return None if check is None else check()

    @property
    def views(self) -> tuple[str, ...]:
        """Constrained views of this run (the ``views`` parameter, default all three)."""
        value = dict(self.params).get("views", VIEWS)
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        return tuple(value)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["params"] = dict(self.params)
        return out


def run_id(exemplar: str, method: str, seed: int, size: int | None = None) -> str:
    """Folder name of a run: ``<exemplar>-<method>[-n<size>]-s<seed>``, file-system safe.

    >>> run_id("etr:snow", "NP_K", 2)
    'etr_snow-NP_K-s2'
    """
    stem = re.sub(r"[^A-Za-z0-9_.+-]+", "_", exemplar).strip("_") or "exemplar"
    middle = f"-n{size}" if size is not None else ""
    return f"{stem}-{method}{middle}-s{seed}"


@dataclass(frozen=True)
class Study:
    """A named comparison: methods crossed with the exemplars, seeds and sizes of a variant.

    Attributes
    ----------
    name : str
        Command-line name (``npmrf3d study NAME``) and output folder.
    title, question : str
        What is compared and what the study answers (shown in the report).
    methods : tuple of Method
    full, quick : Scale
    common : tuple of (name, value) pairs
        ``npmrf`` keyword arguments shared by every run of the study.
    figures : tuple of str
        Extra figures besides ``metrics.png`` and ``slices.png``: ``"temperature"`` (global
        temperature curves), ``"two_point"`` (ground-truth two-point correlations).
    needs_volume : bool
        The study compares with a real 3-D volume (``--volume``).
    notes : str
        Further explanation for the report.
    """

    name: str
    title: str
    question: str
    methods: tuple[Method, ...]
    full: Scale
    quick: Scale
    common: Params = ()
    figures: tuple[str, ...] = ()
    needs_volume: bool = False
    notes: str = ""

    def __post_init__(self):
        object.__setattr__(self, "common", _params(self.common))
        names = [m.name for m in self.methods]
        if len(set(names)) != len(names):
            raise ParameterError(f"study {self.name}: method names must be distinct; got {names}")

    def scale(self, mode: str) -> Scale:
        if mode not in MODES:
            raise ParameterError(f"mode must be one of {', '.join(MODES)}; got {mode!r}")
        return self.quick if mode == "quick" else self.full

    def check_volume_options(self, reference, *, slice_axis: int = 0, slice_index: int | None = None,
                             slices: int = 1) -> None:
        """Refuse the real volume's options where the study reads none of them (it does not
        compare with a real volume), and a slice index beside three slices (one line each)."""
        if slices not in (1, 3):
            raise ParameterError(f"--slices must be 1 or 3; got {slices!r}")
        if not self.needs_volume:
            unread = [flag for flag, used in (("--volume", reference is not None),
                                              ("--slice-axis", slice_axis != 0),
                                              ("--slice-index", slice_index is not None),
                                              ("--slices", slices != 1)) if used]
            if unread:
                raise ParameterError(f"{unread[0]} changes nothing in study {self.name}, which "
                                     "compares with no real volume; drop it")
        if slices == 3 and slice_index is not None:
            raise ParameterError("--slice-index picks one slice; with --slices 3 each view takes "
                                 "its own middle slice")
        if slices == 3 and slice_axis != 0:
            raise ParameterError("--slice-axis picks the axis of one slice; with --slices 3 each "
                                 "view takes the middle slice in its own plane: drop it")

    def runs(self, mode: str = "full", *, seeds=None, exemplars=None, sizes=None,
             levels: int | None = None, reference: str | None = None, slice_axis: int = 0,
             slice_index: int | None = None, slices: int = 1) -> tuple[RunSpec, ...]:
        """The grid of one variant, as run specifications in a fixed order.

        ``seeds``, ``exemplars``, ``sizes`` and ``levels`` replace the variant's values when given.
        ``reference`` (a real volume) is required when :attr:`needs_volume`; ``slices`` (1 or 3)
        says how many of its slices the methods see.
        """
        self.check_volume_options(reference, slice_axis=slice_axis, slice_index=slice_index,
                                  slices=slices)
        scale = self.scale(mode)
        seeds = tuple(int(s) for s in (scale.seeds if seeds is None else seeds))
        sizes = tuple(int(s) for s in (scale.sizes if sizes is None else sizes))
        exemplars = tuple(scale.exemplars if exemplars is None else exemplars)
        levels = scale.levels if levels is None else int(levels)
        if self.needs_volume:
            if reference is None:
                raise ParameterError(f"study {self.name} compares with a real 3-D volume: "
                                     f"give one with --volume FILE (.npy or .tif)")
            stem = re.sub(r"\W+", "_", str(reference).replace("\\", "/").rsplit("/", 1)[-1]
                          .rsplit(".", 1)[0])
            exemplars = (f"{stem}.axis{slice_axis}" if slices == 1 else f"{stem}.three_slices",)
        if not seeds or not sizes or not exemplars:
            raise ParameterError(f"study {self.name}: seeds, sizes and exemplars must not be empty")
        methods = self.methods if scale.methods is None else scale.methods
        common = dict(self.common)
        common.update(scale.common)
        specs = []
        for exemplar in exemplars:
            for method in methods:
                params = {}
                if method.algorithm == "npmrf":  # the common settings the method's sampler uses
                    where = combination({**common, **dict(method.params)})
                    params = {k: v for k, v in common.items() if applies(k, where)}
                params.update(method.params)
                for size in sizes:
                    for seed in seeds[:method.max_seeds]:
                        specs.append(RunSpec(
                            study=self.name,
                            run_id=run_id(exemplar, method.name, seed,
                                          size if len(sizes) > 1 else None),
                            exemplar=exemplar, method=method.name, algorithm=method.algorithm,
                            seed=seed, size=size, levels=levels, params=_params(params),
                            crop=scale.crop,
                            reference=None if reference is None else str(reference),
                            slice_axis=slice_axis, slice_index=slice_index, slices=slices,
                        ))
        ids = [s.run_id for s in specs]
        if len(set(ids)) != len(ids):
            raise ParameterError(f"study {self.name}: run ids are not unique (repeated seeds, "
                                 f"sizes or exemplars?)")
        return tuple(specs)

    def to_dict(self) -> dict[str, Any]:
        """Plain description of the declaration (for ``study.json`` and the report)."""

        def method(m: Method) -> dict:
            return {"name": m.name, "algorithm": m.algorithm, "params": dict(m.params),
                    "max_seeds": m.max_seeds}

        def scale(s: Scale) -> dict:
            d = asdict(s)
            d["common"] = dict(s.common)
            d["methods"] = None if s.methods is None else [method(m) for m in s.methods]
            return d

        return {
            "name": self.name, "title": self.title, "question": self.question,
            "notes": self.notes, "common": dict(self.common),
            "methods": [method(m) for m in self.methods],
            "quick": scale(self.quick), "full": scale(self.full),
            "figures": list(self.figures), "needs_volume": self.needs_volume,
        }

    def with_scale(self, mode: str, **changes) -> "Study":
        """A copy whose ``mode`` variant has some fields replaced (tests, ad-hoc runs)."""
        return replace(self, **{mode: replace(self.scale(mode), **changes)})
