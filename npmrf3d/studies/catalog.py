"""The studies of Urs et al. 2014 (and the 2D->3D ground-truth study), declared as data.

Each entry of :data:`STUDIES` is a :class:`~npmrf3d.studies.grid.Study`: methods crossed with
the exemplars, seeds and sizes of a ``full`` and a ``quick`` variant. Change a comparison by
editing its declaration here; the runner, the figures and the report need nothing else.

Full variants run at the paper's scale: 64^3 volumes, 3 pyramid levels, the exemplars' top-left
64 x 64 pixels, 3 seeds (so that tables give mean +- standard deviation and the report says
which differences exceed the spread). A full-Parzen run costs 1.5-3 CPU minutes at that scale,
so each study's exemplar list is short: one or two exemplars chosen for what the study asks
(``--exemplars`` runs others; the NP_K study's full list of 14 is :data:`STUDY_EXEMPLARS`).
Quick variants are tiny (8^3 to 16^3, one level or two, small windows, two sweeps) so that the
tests run every study.

Exemplars
---------
Names resolve with :func:`load_exemplar`:

* a bundled exemplar (:func:`npmrf3d.data.available`): real photographs and micrographs from
  scikit-image, CC0 / public domain (``npmrf3d/data/SOURCES.md``);
* ``etr:<name>``: a terrain photograph of Debian's ``extremetuxracer-data`` package, read at
  run time from :data:`ETR_DIR` when the package is installed (GPL-2+, never bundled);
* any other string is an image file path (``.png``, ``.tif``, ``.npy`` ...).
"""

from __future__ import annotations

from ..errors import ParameterError
from ..model.exemplar import ETR_DIR, etr_available, named_exemplar  # noqa: F401 (re-exported)
from .grid import Method, Scale, Study

__all__ = [
    "COLOUR_EXEMPLARS",
    "ETR_DIR",
    "GREY_EXEMPLARS",
    "LAYERED_EXEMPLARS",
    "NPK_FULL_EXEMPLARS",
    "STUDIES",
    "STUDY_EXEMPLARS",
    "etr_available",
    "get_study",
    "load_exemplar",
]

#: The ~15 real exemplars of the comparison with NP_K: grey and colour, stochastic and
#: structured, layered/anisotropic, micro-structure-like (all bundled, see SOURCES.md).
STUDY_EXEMPLARS: tuple[str, ...] = (
    # grey
    "gravel", "brick", "grass", "lawn", "microaneurysms", "phase_bands", "pompeii_coins",
    # colour
    "ihc", "hubble", "wood", "tabby_fur", "retina_vessels", "rocket_truss", "stripes",
)
#: Grey exemplars (ICM versus annealing on 32 grey levels, the heuristics).
GREY_EXEMPLARS: tuple[str, ...] = ("gravel64", "brick", "lawn", "phase_bands")
#: Colour exemplars (annealing in colour).
COLOUR_EXEMPLARS: tuple[str, ...] = ("ihc64", "hubble", "wood", "tabby_fur", "retina_vessels")
#: Layered / anisotropic exemplars whose layers run along the image rows (two versus three views).
LAYERED_EXEMPLARS: tuple[str, ...] = ("stripes", "wood", "tabby_fur", "phase_bands", "brick")

#: A study exemplar by name (:func:`npmrf3d.model.exemplar.named_exemplar`).
load_exemplar = named_exemplar


# --------------------------------------------------------------------------- the studies

# Shared pieces of the declarations.
#: The paper's scale with spread: 64^3, 3 levels, 64 x 64 crops, 3 seeds (studies/README.md
#: gives the wall times on the project's 2-core machine).
_FULL = dict(seeds=(0, 1, 2), sizes=(64,), levels=3, crop=64)
#: The NP_K comparison's exemplars in its full variant: grey stochastic and structured, colour
#: stochastic (each exemplar costs about a quarter of an hour of the 2-core machine at this scale;
#: ``--exemplars`` runs the other eleven of STUDY_EXEMPLARS).
NPK_FULL_EXEMPLARS: tuple[str, ...] = ("gravel", "brick", "ihc")
_QUICK = dict(exemplars=("gravel64",), seeds=(0,), sizes=(8,), levels=1, crop=24,
              common=(("window", 3), ("max_sweeps", 2)))
_ANNEAL = (("relaxation", "anneal"), ("support", "full"), ("sampler", "metropolis"),
           ("schedule", "geometric"), ("proposals", 8))
_QUICK_ANNEAL = (("proposals", 2),)
#: The on-demand neural generator (Gutierrez et al. 2020) in the NP_K comparison. Full: the
#: paper's network (85,003 parameters) trained for NEURAL_ITERATIONS steps of one 64^2 slice per
#: view (about 1.5 s a step on one core for a grey exemplar, so about 4 minutes per exemplar;
#: colour costs a little more). Quick: a tiny network (3 scales, about 1,000 parameters) for 3
#: steps.
NEURAL_ITERATIONS = 150
_NEURAL = Method("neural", "neural", (("iterations", NEURAL_ITERATIONS),))
_QUICK_NEURAL = Method("neural", "neural", (
    ("iterations", 3), ("scales", 3), ("noise_channels", 2), ("channel_step", 2), ("tile", 16),
    ("filters", 6), ("descriptor_scales", 2), ("filter_size", 3), ("slice_size", 16)))


def _m(name: str, algorithm: str = "npmrf", **params) -> Method:
    """A study column: ``algorithm`` with ``params`` (the NP-MRF sampler's support: coherent,
    unless named)."""
    return Method(name, algorithm, tuple(params.items()))


def _full(name: str, **params) -> Method:
    """A reproduction row: the NP-MRF sampler with the paper's full-Parzen support (every
    exemplar patch in each view's estimate, a 64-colour palette), on the first seed only: one
    such run costs 3-6 minutes of one core at the paper's scale, and the coherent rows beside it
    show the spread over seeds."""
    return Method(name, "npmrf", tuple({"support": "full", "palette": 64, **params}.items()),
                  max_seeds=1)


#: synth's default (ICM, the coherent NP-MRF sampler, full colours): the studies that compare
#: sampler settings show it beside them.
_DEFAULT = _m("default", relaxation="icm", support="coherent", palette=None)
#: The coherent support annealed over its candidates (docs/model.md, section 8), full colours.
_COHERENT_ANNEAL = _m("coherent-anneal", relaxation="anneal", support="coherent", sampler="heat-bath",
                      proposals=4, palette=None)
#: ICM with the paper's per-voxel temperatures (docs/model.md, section 6) over coherent candidates.
_TEMPERATURES = (("temperatures", True),)

HEURISTICS = Study(
    name="heuristics",
    title="Heuristics compared: ML_H1a, ML_H1b, ML_H2a, ML_H2b",
    question="Which way of making one voxel value from three 2D views gives the best volumes?",
    notes="ICM, 7x7 windows, 8/8 up-sampling. The main rows run each heuristic over the "
          "coherent candidates (full colours) with synth's ICM (every voxel re-decided in each "
          "of a level's iterations; per-voxel temperatures are the cooling study's subject); "
          "the '-full' rows reproduce the paper: the full-Parzen support with the paper's "
          "literal rule (argmax, h_opt), per-voxel temperatures, resynth, xi = -3, stop at 95 %, "
          "one seed, 64 grey levels. ML_H1b averages the views' best values, so it makes values "
          "the exemplar does not have (a washed-out volume), as the paper shows.",
    common=(("relaxation", "icm"), ("window", 7), ("upsample", "8/8"), ("inherit", "resynth"),
            ("xi", -3.0), ("stop", 0.95), ("max_sweeps", 30)),
    methods=(
        _m("ML_H1a", heuristic="ML_H1a"),
        _m("ML_H1b", heuristic="ML_H1b"),
        _m("ML_H2a", heuristic="ML_H2a"),
        _m("ML_H2b", heuristic="ML_H2b"),
        _full("ML_H1a-full", heuristic="ML_H1a", preset="paper"),
        _full("ML_H1b-full", heuristic="ML_H1b", preset="paper"),
        _full("ML_H2a-full", heuristic="ML_H2a", preset="paper"),
        _full("ML_H2b-full", heuristic="ML_H2b", preset="paper"),
    ),
    full=Scale(exemplars=("gravel64",), **_FULL),
    quick=Scale(**_QUICK),
)

COOLING = Study(
    name="cooling",
    title="ICM cooling: xi = -1 versus -3, full versus 95 % stop",
    question="How fast should voxels cool, and does stopping at 95 % of the global temperature "
             "lose anything against cooling down to 0?",
    notes="ML_H2b, ICM with per-voxel temperatures over coherent candidates, 7x7, 8/8, "
          "resynth; the '-full' rows reproduce the paper with the full-Parzen support (tuned "
          "rule, one seed). The temperature figure shows the global temperature (sum of voxel "
          "temperatures) after each sweep, levels one after the other; its numbers are in "
          "temperature.csv.",
    common=(("relaxation", "icm"), ("heuristic", "ML_H2b"), ("window", 7), ("upsample", "8/8"),
            ("inherit", "resynth"), ("max_sweeps", 60), *_TEMPERATURES),
    methods=(
        _m("xi-1-to0", xi=-1.0, stop=1.0),
        _m("xi-1-stop95", xi=-1.0, stop=0.95),
        _m("xi-3-to0", xi=-3.0, stop=1.0),
        _m("xi-3-stop95", xi=-3.0, stop=0.95),
        _full("xi-1-stop95-full", xi=-1.0, stop=0.95),
        _full("xi-3-stop95-full", xi=-3.0, stop=0.95),
    ),
    full=Scale(exemplars=("gravel64",), **_FULL),
    quick=Scale(**{**_QUICK, "common": (("window", 3), ("max_sweeps", 4))}),
    figures=("temperature",),
)

NEIGHBOURHOOD = Study(
    name="neighbourhood",
    title="Neighbourhood size (9x9, 11x11) crossed with 1/8 versus 8/8 up-sampling",
    question="Do larger neighbourhoods capture larger structures, and which up-sampling keeps "
             "them across scales?",
    notes="ML_H2b, ICM with per-voxel temperatures, resynth, stop at 95 %, each support's "
          "default xi (-1 over coherent candidates, the paper's -3 with the full-Parzen support); "
          "the '-full' rows reproduce the paper's 9x9 with the full-Parzen support (tuned rule, "
          "one seed). The quick variant uses 3x3 and 5x5 windows on 16^3 volumes.",
    common=(("relaxation", "icm"), ("heuristic", "ML_H2b"), ("inherit", "resynth"),
            ("stop", 0.95), ("max_sweeps", 30), *_TEMPERATURES),
    methods=(
        _m("w9-1of8", window=9, upsample="1/8"),
        _m("w9-8of8", window=9, upsample="8/8"),
        _m("w11-1of8", window=11, upsample="1/8"),
        _m("w11-8of8", window=11, upsample="8/8"),
        _full("w9-1of8-full", window=9, upsample="1/8"),
        _full("w9-8of8-full", window=9, upsample="8/8"),
    ),
    full=Scale(exemplars=("brick",), **_FULL),
    quick=Scale(exemplars=("gravel64",), seeds=(0,), sizes=(16,), levels=2, crop=24,
                common=(("max_sweeps", 2),),
                methods=(_m("w3-1of8", window=3, upsample="1/8"),
                         _m("w3-8of8", window=3, upsample="8/8"),
                         _m("w5-1of8", window=5, upsample="1/8"),
                         _m("w5-8of8", window=5, upsample="8/8"),
                         _full("w3-1of8-full", window=3, upsample="1/8"))),
)

ICM_VS_ANNEAL = Study(
    name="icm_vs_anneal",
    title="ICM versus simulated annealing on 32-level grey exemplars",
    question="Does ICM lose the exemplar's dynamics (grey-level range) where annealing keeps it?",
    notes="ML_H2b, 7x7, exemplars re-quantised to 32 grey levels. Main rows over coherent "
          "candidates: ICM with per-voxel temperatures (xi = -1) and 1/8 up-sampling, "
          "annealing with the Metropolis step and with the heat-bath draw (8/8). The '-full' "
          "rows reproduce the paper with the full-Parzen support, one seed: ICM with the literal "
          "rule, and Metropolis annealing (geometric schedule, 8 proposals per voxel and level).",
    common=(("heuristic", "ML_H2b"), ("window", 7), ("grey_levels", 32)),
    methods=(
        _m("ICM", relaxation="icm", upsample="1/8", max_sweeps=30, **dict(_TEMPERATURES)),
        _m("anneal-metropolis", relaxation="anneal", sampler="metropolis"),
        _m("anneal-heat-bath", relaxation="anneal", sampler="heat-bath"),
        _full("ICM-full", relaxation="icm", preset="paper", max_sweeps=30),
        _full("anneal-full", **dict(_ANNEAL)),
    ),
    full=Scale(exemplars=("gravel64",), **_FULL),
    quick=Scale(**{**_QUICK, "common": (("window", 3), ("max_sweeps", 2), *_QUICK_ANNEAL)}),
)

COLOUR = Study(
    name="colour",
    title="Colour exemplars with simulated annealing and ML_H2b",
    question="Does annealing with ML_H2b reproduce colour textures, as Urs et al. 2014 "
             "(section V.E) show it doing?",
    notes="ML_H2b, 7x7. Main rows over coherent candidates on the full colours: annealing with "
          "the Metropolis step and the heat-bath draw, and ICM ('default', synth's default) as "
          "the reference. The '-full' rows reproduce the paper: the full-Parzen support with a "
          "64-colour palette (k-means), geometric schedule, 8 proposals per voxel and level, "
          "one seed.",
    common=(("heuristic", "ML_H2b"), ("window", 7)),
    methods=(
        _m("anneal-metropolis", relaxation="anneal", sampler="metropolis"),
        _m("anneal-heat-bath", relaxation="anneal", sampler="heat-bath"),
        _DEFAULT,
        _full("anneal-metropolis-full", **dict(_ANNEAL)),
        _full("anneal-heat-bath-full", **{**dict(_ANNEAL), "sampler": "heat-bath"}),
    ),
    full=Scale(exemplars=("ihc64",), **_FULL),
    quick=Scale(**{**_QUICK, "exemplars": ("ihc64",),
                   "common": (("window", 3), ("max_sweeps", 2), *_QUICK_ANNEAL)}),
)

NPK = Study(
    name="npk",
    title="ML_H2b (annealing) versus NP_K on ~15 real exemplars",
    question="How does the NP-MRF with annealing compare with texture optimisation (NP_K) on "
             "histogram KL, autocorrelation L2 and orientation KL?",
    notes="ML_H2b annealed over coherent candidates on the full colours, with the paper's "
          "Metropolis step ('ML_H2b-anneal') and the heat-bath draw ('coherent-anneal', 4 "
          "proposals per level); 'ML_H2b-anneal-full' reproduces the paper: the full-Parzen "
          "support, a 64-colour palette (64 levels for grey exemplars), one seed. NP_K: Kopf et al. 2007 as implemented in "
          "npmrf3d.methods.kopf with its default settings and the study's levels. 'control' is "
          "the structureless control (voxels drawn independently from the exemplar): a method "
          "no better than it made no structure. 'default' is synth's default (the coherent "
          "NP-MRF sampler, ICM, 7x7 at every level) and 'coherent' the coherent method with its "
          "own windows (8, 6, 4); all on the full colours, no palette. "
          "'neural' is the on-demand 3D CNN generator (Gutierrez et al. 2020; "
          "npmrf3d.methods.neural) trained on the same exemplar (150 steps of one 64x64 "
          "slice per view, Gram and value-histogram loss), its train and generate seconds "
          "apart; it needs the optional extra npmrf3d[neural] (torch) and is left out, with a "
          "note in study.json, where that is not installed.",
    common=(("heuristic", "ML_H2b"), ("window", 7)),
    methods=(
        _m("ML_H2b-anneal", relaxation="anneal", sampler="metropolis"),
        _full("ML_H2b-anneal-full", **dict(_ANNEAL)),
        _m("NP_K", "kopf", window=8),
        _m("chen-wang", "chen-wang"),
        _m("coherent", "coherent"),
        _DEFAULT,
        _COHERENT_ANNEAL,
        _NEURAL,
        _m("control", "control"),
    ),
    full=Scale(exemplars=NPK_FULL_EXEMPLARS, **_FULL),
    quick=Scale(exemplars=("gravel64",), seeds=(0,), sizes=(8,), levels=1, crop=24,
                common=(("window", 3), *_QUICK_ANNEAL),
                methods=(_m("ML_H2b-anneal", relaxation="anneal", sampler="metropolis"),
                         _full("ML_H2b-anneal-full", **dict(_ANNEAL)),
                         _m("NP_K", "kopf", window=4, iterations=1),
                         _QUICK_NEURAL, _m("control", "control"))),
)

VIEWS = Study(
    name="views",
    title="Two versus three constrained views on layered exemplars",
    question="For layered textures, does constraining only the two views that contain the "
             "layering direction (front and top) avoid the conflict a third view creates?",
    notes="The exemplars' layers run along the image rows, i.e. along axis i in the front "
          "(i, j) and top (i, k) views; the right view (j, k) would ask for layers along j too. "
          "ML_H2b, ICM, 7x7. Main rows: synth's default (the coherent NP-MRF sampler) on the "
          "full colours; the '-full' rows reproduce the paper with the full-Parzen support (tuned "
          "rule, 64-colour palette: the photographs have thousands of distinct colours), one "
          "seed. Metrics are computed on the constrained views only.",
    common=(("relaxation", "icm"), ("heuristic", "ML_H2b"), ("window", 7), ("max_sweeps", 30)),
    methods=(
        _m("3views", views="front,right,top"),
        _m("2views", views="front,top"),
        _full("3views-full", views="front,right,top"),
        _full("2views-full", views="front,top"),
    ),
    full=Scale(exemplars=("wood",), **_FULL),
    quick=Scale(**{**_QUICK, "exemplars": ("stripes",)}),
)

GROUNDTRUTH = Study(
    name="groundtruth",
    title="2D -> 3D ground truth: one slice of a real volume in, the volume itself as the truth",
    question="Given one slice of a real 3-D micro-structure, how close in 3-D (two-point "
             "correlation along each axis, phase or grey-level fractions, slice metrics along "
             "all three axes) do the methods get, against a structureless control?",
    notes="The exemplar is one slice of --volume (default: the middle slice across axis 0), "
          "used for all three views. 'real' is a crop of the real volume (the floor set by "
          "finite size); 'control' draws voxels independently from the exemplar. Slice "
          "metrics compare each view's slices with the real volume's middle slice in that view. "
          "'default' is synth's default (the coherent NP-MRF sampler); 'ML_H2b-icm' adds the "
          "per-voxel temperatures, 'ML_H2b-anneal' anneals over the coherent candidates "
          "(Metropolis) and 'ML_H2b-anneal-full' is the paper's full-Parzen annealer (one seed).",
    common=(("heuristic", "ML_H2b"), ("window", 7), ("max_sweeps", 30)),
    methods=(
        _m("ML_H2b-icm", relaxation="icm", **dict(_TEMPERATURES)),
        _m("ML_H2b-anneal", relaxation="anneal", sampler="metropolis"),
        _full("ML_H2b-anneal-full", **dict(_ANNEAL)),
        _m("NP_K", "kopf", window=8),
        _DEFAULT,
        _m("chen-wang", "chen-wang"),
        _m("control", "control"),
        _m("real", "real"),
    ),
    full=Scale(exemplars=("volume",), seeds=(0, 1, 2), sizes=(64,), levels=3),
    quick=Scale(exemplars=("volume",), seeds=(0,), sizes=(16,), levels=1,
                common=(("window", 3), ("max_sweeps", 2), *_QUICK_ANNEAL),
                methods=(_m("ML_H2b-icm", relaxation="icm", **dict(_TEMPERATURES)),
                         _full("ML_H2b-anneal-full", **dict(_ANNEAL)),
                         _m("NP_K", "kopf", window=4, iterations=1),
                         _m("control", "control"), _m("real", "real"))),
    figures=("two_point",),
    needs_volume=True,
)

#: Every study by name, in the order of the paper's results (Urs et al. 2014, sections V-VII;
#: ground truth last).
STUDIES: dict[str, Study] = {s.name: s for s in (
    HEURISTICS, COOLING, NEIGHBOURHOOD, ICM_VS_ANNEAL, COLOUR, NPK, VIEWS, GROUNDTRUTH)}


def get_study(name: str) -> Study:
    """The study called ``name`` (:class:`ParameterError` listing the names otherwise)."""
    try:
        return STUDIES[name]
    except KeyError:
        raise ParameterError(f"study must be one of {', '.join(STUDIES)}; got {name!r}") from None
