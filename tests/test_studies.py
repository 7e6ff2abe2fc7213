"""Studies on Dask: declarations, every study in quick mode, resuming, failures, serial == Dask,
the HTML report and the 2D -> 3D ground-truth measures."""

from __future__ import annotations

import dataclasses
import html.parser
import json
import sys

import numpy as np
import pytest

import npmrf3d.methods
import npmrf3d.model.exemplar
from npmrf3d import _cluster, cli
from npmrf3d.errors import ParameterError
from npmrf3d.studies import (
    STUDIES,
    Method,
    Scale,
    Study,
    catalog,
    execute,
    get_study,
    groundtruth,
    report,
    run_study,
    table,
)

TINY = Scale(exemplars=("gravel64",), seeds=(0,), sizes=(8,), levels=1, crop=24,
             common=(("window", 3), ("max_sweeps", 2)))


def _study(name, *methods):
    return Study(name=name, title=name, question="?", methods=methods, full=TINY, quick=TINY)


GOOD = Method("H2b", params=(("heuristic", "ML_H2b"),))
CONTROL = Method("control", "control")
BROKEN = Method("broken", params=(("window", 4),))  # even window: refused up front, or (check=False)
#                                                    a ParameterError in the run


@pytest.fixture(scope="module")
def blobs(tmp_path_factory):
    from skimage.data import binary_blobs

    volume = binary_blobs(length=32, n_dim=3, volume_fraction=0.4, rng=3).astype(np.uint8)
    path = tmp_path_factory.mktemp("volume") / "blobs.npy"
    np.save(path, volume)
    return path


@pytest.fixture(scope="module")
def quick_results(tmp_path_factory, blobs):
    """Every study in quick mode, serially, into one results root."""
    out = tmp_path_factory.mktemp("results")
    outcomes = {}
    for name, study in STUDIES.items():
        outcomes[name] = run_study(study, mode="quick", out=out, scheduler="serial",
                                   volume=blobs if study.needs_volume else None,
                                   progress=False, echo=None)
    return out, outcomes


@pytest.fixture(scope="module")
def cluster():
    with _cluster.local_cluster(2) as local:
        yield local.scheduler_address


# --------------------------------------------------------------------------- declarations


def test_catalog_declares_the_seven_studies_and_ground_truth():
    assert list(STUDIES) == ["heuristics", "cooling", "neighbourhood", "icm_vs_anneal", "colour",
                             "npk", "views", "groundtruth"]
    for study in STUDIES.values():
        kw = {"reference": "x.npy"} if study.needs_volume else {}
        for mode in ("quick", "full"):
            runs = study.runs(mode, **kw)
            assert runs and len({r.run_id for r in runs}) == len(runs)
        quick = study.runs("quick", **kw)
        assert max(r.size for r in quick) <= 16 and max(r.levels for r in quick) <= 2
        assert {r.seed for r in quick} == {0}
    assert {r.method for r in STUDIES["heuristics"].runs()} >= {"ML_H1a", "ML_H1b", "ML_H2a",
                                                                "ML_H2b"}
    npk = STUDIES["npk"].runs("full")
    assert {r.algorithm for r in npk} == {"npmrf", "kopf", "chen-wang", "coherent", "neural", "control"}
    assert {r.exemplar for r in npk} == set(catalog.NPK_FULL_EXEMPLARS)
    assert len({r.exemplar for r in STUDIES["npk"].runs("full", exemplars=catalog.STUDY_EXEMPLARS)}) >= 14
    assert all(dict(r.params)["relaxation"] == "anneal" for r in npk
               if r.algorithm == "npmrf" and r.method != "default")
    assert {r.method for r in npk} >= {"default", "coherent-anneal", "ML_H2b-anneal-full"}
    # the main rows run over coherent candidates on every seed, the paper's full-Parzen
    # reproduction rows on the first seed only
    for study in STUDIES.values():
        runs = study.runs("full", **({"reference": "x.npy"} if study.needs_volume else {}))
        full = [r for r in runs if dict(r.params).get("support") == "full"]
        assert full and {r.seed for r in full} == {0}, study.name
        main = [r for r in runs if r.algorithm == "npmrf" and r not in full]
        assert main and {r.seed for r in main} == {0, 1, 2}, study.name
    views = {dict(r.params)["views"] for r in STUDIES["views"].runs()}
    assert views == {"front,right,top", "front,top"}
    with pytest.raises(ParameterError, match="heuristics, cooling"):
        get_study("nope")
    with pytest.raises(ParameterError, match="--volume"):
        STUDIES["groundtruth"].runs("quick")


def test_full_variants_are_at_the_papers_scale_with_three_seeds():
    """The paper's scale: 64^3, 3 levels, 64 x 64 crops (the ground truth: the volume's slice),
    3 seeds, in every study's full variant."""
    for study in STUDIES.values():
        full = study.scale("full")
        assert full.sizes == (64,) and full.levels == 3 and full.seeds == (0, 1, 2), study.name
        assert full.crop == (None if study.needs_volume else 64), study.name
        assert len(full.exemplars) >= 1
    assert set(catalog.NPK_FULL_EXEMPLARS) <= set(catalog.STUDY_EXEMPLARS)


def test_npk_declares_the_neural_method_in_both_modes():
    """Declared whatever is installed; the runner leaves it out where torch is missing."""
    full = [r for r in STUDIES["npk"].runs("full") if r.algorithm == "neural"]
    quick = [r for r in STUDIES["npk"].runs("quick") if r.algorithm == "neural"]
    assert len(full) == 3 * len(catalog.NPK_FULL_EXEMPLARS) and len(quick) == 1
    kwargs = full[0].kwargs()
    assert kwargs == {"iterations": catalog.NEURAL_ITERATIONS, "size": 64, "rng": 0}  # no "levels"
    assert 100 <= catalog.NEURAL_ITERATIONS <= 300
    tiny = quick[0].kwargs()
    assert tiny["iterations"] <= 5 and tiny["scales"] <= 3 and tiny["size"] == 8
    for run in (full[0], quick[0]):  # the declared options are valid without torch
        config = npmrf3d.methods.METHODS["neural"].make_config(
            **{k: v for k, v in run.kwargs().items() if k != "rng"})
        assert config.size == (run.size,) * 3
    assert "levels" in [r for r in STUDIES["npk"].runs("full") if r.algorithm == "kopf"][0].kwargs()


def test_a_method_without_its_extra_is_left_out_and_said(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)  # as if torch were not installed
    neural = Method("neural", "neural", (("iterations", 1),))
    study = _study("extra", neural, CONTROL)
    messages = []
    outcome = run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=messages.append)
    assert [r["method"] for r in outcome.rows] == ["control"] and outcome.counts["done"] == 1
    assert not (tmp_path / "extra" / "gravel64-neural-s0").exists()
    info = json.loads((tmp_path / "extra" / "study.json").read_text())
    [note] = info["left_out"]
    assert note["method"] == "neural" and note["algorithm"] == "neural" and note["runs"] == 1
    assert 'needs torch, which is not installed' in note["reason"]
    assert 'pip install "npmrf3d[neural]"' in note["reason"]
    assert [r["method"] for r in info["runs"]] == ["control"]
    assert any(m.startswith("left out: method neural (1 runs): the neural method needs torch") for m in messages)
    assert [r["method"] for r in table.read_results(tmp_path / "extra" / "results.csv")] == ["control"]
    page = report.build_report(tmp_path / "extra")
    assert "left out: neural" in page and "npmrf3d[neural]" in page
    with pytest.raises(ParameterError, match="no method can run here: the neural method needs torch"):
        run_study(_study("only", neural), out=tmp_path, scheduler="serial", progress=False, echo=None)


def test_overrides_and_kwargs():
    study = STUDIES["cooling"]
    runs = study.runs("full", seeds=[5, 6], exemplars=["brick"], sizes=[16], levels=1)
    assert {(r.seed, r.exemplar, r.size, r.levels) for r in runs} == {
        (5, "brick", 16, 1), (6, "brick", 16, 1)}
    kwargs = runs[0].kwargs()
    assert kwargs["rng"] == 5 and kwargs["size"] == 16 and kwargs["xi"] == -1.0
    assert kwargs["window"] == 7 and kwargs["heuristic"] == "ML_H2b"


def test_study_exemplars_load():
    names = catalog.STUDY_EXEMPLARS + catalog.GREY_EXEMPLARS + catalog.COLOUR_EXEMPLARS \
        + catalog.LAYERED_EXEMPLARS
    channels = set()
    for name in set(names):
        image = catalog.load_exemplar(name)
        assert image.dtype == np.float32 and 64 <= min(image.shape[:2]) <= 128
        channels.add(image.shape[2])
    assert channels == {1, 3}
    assert catalog.load_exemplar("brick", crop=20).shape == (20, 20, 1)
    with pytest.raises(ParameterError, match="unknown exemplar"):
        catalog.load_exemplar("marble")


def test_etr_terrains_only_at_run_time(monkeypatch, tmp_path):
    monkeypatch.setattr(npmrf3d.model.exemplar, "ETR_DIR", tmp_path / "missing")
    with pytest.raises(ParameterError, match="extremetuxracer-data.*not bundled"):
        catalog.load_exemplar("etr:snow")
    assert catalog.etr_available(tmp_path / "missing") == []
    folder = tmp_path / "terrains"
    folder.mkdir()
    import imageio.v3 as iio

    iio.imwrite(folder / "snow.png", np.full((64, 64, 3), 200, np.uint8))
    monkeypatch.setattr(npmrf3d.model.exemplar, "ETR_DIR", folder)
    assert catalog.etr_available() == ["etr:snow"]
    assert catalog.load_exemplar("etr:snow").shape == (64, 64, 3)
    with pytest.raises(ParameterError, match="no terrain photograph 'ice'"):
        catalog.load_exemplar("etr:ice")


def test_plan_workers_never_oversubscribes():
    assert _cluster.plan_workers(None, None, 2) == (2, 1)
    assert _cluster.plan_workers(1, None, 2) == (1, 2)
    with pytest.raises(ParameterError, match="exceed the 2 cores"):
        _cluster.plan_workers(3, None, 2)
    with pytest.raises(ParameterError, match="exceed"):
        _cluster.plan_workers(2, 2, 2)


# --------------------------------------------------------------------------- running


@pytest.mark.parametrize("name", list(STUDIES))
def test_every_study_runs_in_quick_mode(quick_results, name):
    out, outcomes = quick_results
    outcome = outcomes[name]
    study_dir = out / name
    failed = [(r["run_id"], r["error"]) for r in outcome.rows if r["status"] == "failed"]
    assert not failed
    assert outcome.counts["done"] == len(outcome.rows) == len(table.read_results(
        study_dir / "results.csv"))
    for row in outcome.rows:
        run_dir = study_dir / row["run_id"]
        for file in ("volume.npy", "volume.tif", "preview.png", "run.json", "metrics.json"):
            assert (run_dir / file).is_file()
        assert np.isfinite(float(row["mean_histogram_kl"]))
        assert np.isfinite(float(row["mean_autocorrelation_l2"]))
        record = json.loads((run_dir / "run.json").read_text())
        assert record["seed"] == row["seed"] and record["spec"]["run_id"] == row["run_id"]
    for figure in ("metrics.png", "slices.png", *{"temperature": ["temperature.png"],
                                                  "two_point": ["two_point.png"]}.get(
                                                      next(iter(STUDIES[name].figures), ""), [])):
        assert (study_dir / figure).is_file()
    info = json.loads((study_dir / "study.json").read_text())
    assert info["mode"] == "quick" and info["scheduler"] == "serial"


def test_resume_skips_finished_runs(tmp_path):
    study = _study("resume", GOOD, CONTROL)
    first = run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None)
    assert first.counts == {"done": 2, "skipped": 0, "failed": 0}
    stamp = (tmp_path / "resume" / first.rows[0]["run_id"] / "volume.npy").stat().st_mtime_ns
    (tmp_path / "resume" / first.rows[1]["run_id"] / "metrics.json").unlink()  # unfinished
    second = run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None)
    assert [r["status"] for r in second.rows] == ["skipped", "done"]
    assert (tmp_path / "resume" / first.rows[0]["run_id"] / "volume.npy").stat().st_mtime_ns == stamp
    for a, b in zip(first.rows, second.rows):
        assert a["mean_histogram_kl"] == b["mean_histogram_kl"]


def test_failed_run_is_recorded_and_others_go_on(tmp_path):
    study = _study("failing", BROKEN, GOOD)
    with pytest.raises(ParameterError, match="study failing: run gravel64-broken-s0: window"):
        run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None)
    assert not (tmp_path / "failing").exists()
    outcome = run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None,
                        check=False)  # what only a run finds out is a failed row
    broken, good = outcome.rows
    assert broken["status"] == "failed" and good["status"] == "done"
    assert "ParameterError" in broken["error"] and "window" in broken["error"]
    error = json.loads((tmp_path / "failing" / broken["run_id"] / "error.json").read_text())
    assert "Traceback" in error["traceback"] and error["spec"]["method"] == "broken"
    rows = table.read_results(tmp_path / "failing" / "results.csv")
    assert [r["status"] for r in rows] == ["failed", "done"] and rows[0]["error"]
    again = run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None,
                      check=False)
    assert [r["status"] for r in again.rows] == ["failed", "skipped"]  # failures are retried


def test_dask_gives_the_serial_results(tmp_path, cluster):
    study = _study("same", GOOD, CONTROL, BROKEN)
    study = study.with_scale("quick", seeds=(0, 1))
    serial = run_study(study, out=tmp_path / "serial", scheduler="serial", progress=False,
                       echo=None, check=False)
    messages = []
    dask = run_study(study, out=tmp_path / "dask", scheduler=cluster, threads=1,
                     progress=False, echo=messages.append, check=False)
    assert any("dashboard" in m for m in messages)
    assert [r["status"] for r in dask.rows] == [r["status"] for r in serial.rows] == [
        "done", "done", "done", "done", "failed", "failed"]
    for a, b in zip(serial.rows, dask.rows):
        assert a["run_id"] == b["run_id"]
        if a["status"] == "done":
            va = np.load(tmp_path / "serial" / "same" / a["run_id"] / "volume.npy")
            vb = np.load(tmp_path / "dask" / "same" / b["run_id"] / "volume.npy")
            np.testing.assert_array_equal(va, vb)
            assert a["mean_autocorrelation_l2"] == b["mean_autocorrelation_l2"]
            assert json.loads((tmp_path / "dask" / "same" / b["run_id"] / "run.json")
                              .read_text())["threads"] == 1
        else:
            assert a["error"] == b["error"]


# --------------------------------------------------------------------------- report


class _Collector(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids, self.images, self.links = {}, {}, []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids[attrs["id"]] = tag
        if tag == "img":
            self.images[attrs.get("id")] = attrs["src"]
        for key in ("href", "src"):
            if key in attrs and not attrs[key].startswith(("#", "data:")):
                self.links.append(attrs[key])


def test_report_has_every_run_row_and_figure(quick_results, tmp_path):
    out, outcomes = quick_results
    target = tmp_path / "all.html"
    assert cli.main(["report", str(out), "--out", str(target)]) == 0
    parser = _Collector()
    parser.feed(target.read_text(encoding="utf-8"))
    assert not parser.links  # self-contained: opens offline
    for name, outcome in outcomes.items():
        assert parser.ids[f"study-{name}"] == "section"
        for row in outcome.rows:
            assert parser.ids[f"row-{name}-{row['run_id']}"] == "tr"
            assert parser.images[f"fig-{name}-{row['run_id']}"].startswith("data:image/png;base64,")
        assert f"study-fig-{name}-metrics" in parser.images
    one = report.write_report(out / "cooling")
    assert one == out / "cooling" / "report.html"
    text = one.read_text(encoding="utf-8")
    assert "study-fig-cooling-temperature" in text and "xi-1-to0" in text


def test_spread_summary_and_which_leads_exceed_it(tmp_path):
    from npmrf3d.studies.table import separations, summarise

    def row(method, seed, ac, exemplar="e", status="ok"):
        return {"exemplar": exemplar, "method": method, "seed": str(seed), "status": status,
                "mean_ac": str(ac)}
    rows = ([row("a", s, x) for s, x in enumerate((1.0, 1.2, 1.1))]
            + [row("b", s, x) for s, x in enumerate((2.0, 2.1, 1.9))]
            + [row("c", s, x) for s, x in enumerate((1.05, 1.35, 0.95))]
            + [row("c", 9, 0.0, status="failed")]            # failed runs are left out
            + [row("a", 0, 0.5, exemplar="one"), row("b", 0, 0.7, exemplar="one")])
    summary = {(r["exemplar"], r["method"]): r for r in summarise(rows)}
    assert summary[("e", "a")]["n"] == 3 and summary[("e", "c")]["n"] == 3
    np.testing.assert_allclose(summary[("e", "a")]["mean"], 1.1)
    np.testing.assert_allclose(summary[("e", "a")]["std"], np.std([1.0, 1.2, 1.1]))
    verdict = {r["exemplar"]: r for r in separations(list(summary.values()))}
    assert (verdict["e"]["best"], verdict["e"]["runner_up"]) == ("a", "c")
    assert verdict["e"]["exceeds_spread"] is False       # 0.017 apart, spreads 0.08 + 0.17
    assert verdict["one"]["exceeds_spread"] is None      # one seed: unknown
    without_c = [r for r in summary.values() if r["method"] != "c"]
    assert {r["exemplar"]: r["exceeds_spread"] for r in separations(without_c)}["e"] is True
    html_text = report._spread_section(rows)
    assert "Across seeds" in html_text and "<b>1.1 ± 0.082 (3)</b>" in html_text
    assert "no (0.0167" in html_text and "one seed: spread unknown" in html_text


def test_report_shows_failures(tmp_path):
    outcome = run_study(_study("failing", BROKEN, GOOD), out=tmp_path, scheduler="serial",
                        progress=False, echo=None, check=False)
    parser = _Collector()
    text = report.build_report(tmp_path)
    parser.feed(text)
    broken = outcome.rows[0]["run_id"]
    assert parser.ids[f"row-failing-{broken}"] == "tr"
    assert parser.ids[f"fig-failing-{broken}"] == "div"  # no picture, the message instead
    assert "Failures (1)" in text and "ParameterError" in text


# --------------------------------------------------------------------------- command line


def test_cli_study_and_errors(tmp_path, capsys, blobs):
    out = tmp_path / "cli"
    assert cli.main(["study", "views", "--quick", "--out", str(out), "--scheduler", "serial",
                     "--quiet"]) == 0
    assert (out / "views" / "results.csv").is_file()
    assert cli.main(["study", "nope", "--quick"]) == 2
    assert "study must be one of" in capsys.readouterr().err
    assert cli.main(["study", "groundtruth", "--quick", "--out", str(out),
                     "--scheduler", "serial"]) == 2
    assert "--volume" in capsys.readouterr().err
    assert cli.main(["study", "views", "--quick", "--workers", "999", "--out", str(out),
                     "--exemplars", "brick"]) == 2
    assert "exceed" in capsys.readouterr().err
    assert cli.main(["report", str(tmp_path / "empty")]) == 2
    assert cli.main(["study", "--help"]) == 0
    assert "(default: local)" in capsys.readouterr().out


_FRESH_COMPILE_SCRIPT = """
import numba  # a study script imports numba before a spawned worker gets the Nanny's environment
from npmrf3d._cluster import local_cluster


def compile_fresh(x):
    import numba

    numba.set_num_threads(1)  # as execute_run does: the pool starts

    @numba.njit
    def twice(v):  # never cached: compiled in the worker, as on a fresh install
        return 2 * v
    return twice(x)


def allocator_setting():
    import os

    return os.environ.get("MALLOC_MMAP_THRESHOLD_")


if __name__ == "__main__":
    from distributed import Client

    with local_cluster(1) as cluster, Client(cluster) as client:
        print("result", client.submit(compile_fresh, 21).result())
        print("mmap threshold", client.submit(allocator_setting).result())
"""


def test_local_cluster_workers_can_compile_from_a_script(tmp_path):
    """Regression (fresh install, empty numba cache): workers of a cluster started by a study
    script could not compile ("Cannot set NUMBA_NUM_THREADS ... once the threads have been
    launched"), so every run of ``studies/suite.py`` failed."""
    import subprocess

    script = tmp_path / "suite_like.py"
    script.write_text(_FRESH_COMPILE_SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=240, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "result 42" in done.stdout
    # and the allocator setting of npmrf3d._cluster reached the worker before it started
    # (without it a worker's every large allocation is a fresh, zeroed mmap: 41 % kernel time)
    from npmrf3d._cluster import MMAP_THRESHOLD

    assert f"mmap threshold {MMAP_THRESHOLD}" in done.stdout


def test_study_script_entry_point(tmp_path):
    from npmrf3d.cli.study import study_main

    assert study_main("views", ["--quick", "--out", str(tmp_path), "--scheduler", "serial",
                                "--quiet"]) == 0
    assert study_main("views", ["--quick", "--out", str(tmp_path / "other"), "--scheduler",
                                "serial", "--quiet", "--exemplars", "nope.png"]) == 2  # refused up front
    assert not (tmp_path / "other").exists()


# --------------------------------------------------------------------------- ground truth


def test_two_point_and_fractions_against_brute_force():
    rng = np.random.default_rng(0)
    volume = (rng.random((12, 10, 9)) < 0.3).astype(np.float32)
    phases = groundtruth.phases_of(volume[0][..., None])
    assert phases.tolist() == [0.0, 1.0]
    for axis in range(3):
        curve = groundtruth.two_point(volume, axis, 4, phases)[0]
        n = volume.shape[axis]
        for r in range(5):
            pairs = [float(np.take(volume, i, axis) .ravel() @ np.take(volume, i + r, axis).ravel())
                     for i in range(n - r)]
            expected = sum(pairs) / ((n - r) * volume.size / n)
            assert curve[r] == pytest.approx(expected)
        assert curve[0] == pytest.approx(volume.mean())
    fr = groundtruth.fractions(volume, phases, (0.0, 1.0))
    assert fr.tolist() == pytest.approx([1 - volume.mean(), volume.mean()])
    grey = rng.random((16, 16, 16)).astype(np.float32)
    rho = groundtruth.two_point(grey, 1, 3, None)[0]
    assert rho[0] == pytest.approx(1.0) and np.all(np.abs(rho[1:]) < 0.1)


def test_fraction_free_two_point_against_brute_force():
    # the mean over the pairs inside the volume of (I(s) - phi)(I(s + r) - phi) / (phi - phi^2),
    # I the phase indicator and phi the whole volume's fraction, written out pair by pair
    rng = np.random.default_rng(1)
    volume = (rng.random((10, 12, 8)) < 0.35).astype(np.float32)
    phases = np.array([0.0, 1.0])
    phi = float(volume.mean())
    for axis in range(3):
        curve = groundtruth.two_point(volume, axis, 3, phases, normalised=True)[0]
        v = np.moveaxis(volume.astype(np.float64), axis, 0)
        for r in range(4):
            pairs = [(v[(i,) + rest] - phi) * (v[(i + r,) + rest] - phi)
                     for i in range(v.shape[0] - r) for rest in np.ndindex(*v.shape[1:])]
            assert curve[r] == pytest.approx(sum(pairs) / len(pairs) / (phi - phi ** 2))
        assert curve[0] == pytest.approx(1.0)


def test_fraction_free_two_point_does_not_rank_a_structureless_volume_above_structure(blobs):
    real = groundtruth.load_reference(blobs)
    exemplar = groundtruth.exemplar_slice(real, 0)
    control = execute.structureless(exemplar, 32, 0)  # the right fraction, no structure
    # a volume with the real structure but a phase fraction drifted (eroded by one voxel)
    from scipy import ndimage
    labels = real[..., 0] > 0.5
    eroded = ndimage.binary_erosion(labels, iterations=1).astype(np.float32)[..., None]
    noise = groundtruth.compare(control, real, exemplar)
    shrunk = groundtruth.compare(eroded, real, exemplar)
    assert shrunk["fraction_l1"] > noise["fraction_l1"]
    # raw S2 follows the fraction and ranks the structureless volume first (why the shape exists)
    assert shrunk["two_point_l2_mean"] > noise["two_point_l2_mean"]
    assert shrunk["two_point_shape_l2_mean"] < noise["two_point_shape_l2_mean"]
    assert set(shrunk["two_point_shape_l2"]) == {"axis0", "axis1", "axis2"}


def test_ground_truth_compare_ranks_structure(blobs):
    real = groundtruth.load_reference(blobs)
    exemplar = groundtruth.exemplar_slice(real, 0)
    np.testing.assert_array_equal(exemplar, real[16])
    same = groundtruth.compare(real, real, exemplar)
    assert same["two_point_l2_mean"] == 0 and same["fraction_l1"] == 0
    control = execute.structureless(exemplar, 32, 0)
    noise = groundtruth.compare(control, real, exemplar)
    assert noise["two_point_l2_mean"] > 0.1 and noise["fraction_l1"] < 0.1
    assert set(noise["slice_metrics"]["per_view"]) == {"front", "right", "top"}
    assert groundtruth.fit_size(real.shape, 64, 2) == 32
    with pytest.raises(ParameterError, match="slice index"):
        groundtruth.exemplar_slice(real, 1, 40)


def test_ground_truth_three_slices_give_each_view_its_own_plane(blobs):
    real = groundtruth.load_reference(blobs)
    one = groundtruth.exemplar_slices(real, 1, 2, 5)
    assert {id(a) for a in one.values()} == {id(one["front"])}  # one array for every view
    np.testing.assert_array_equal(one["top"], real[:, :, 5])
    three = groundtruth.exemplar_slices(real, 3)
    np.testing.assert_array_equal(three["front"], real[:, :, 16])  # front: axes 0-1
    np.testing.assert_array_equal(three["right"], real[16])         # right: axes 1-2
    np.testing.assert_array_equal(three["top"], real[:, 16])        # top: axes 0-2
    pooled = groundtruth.pooled_exemplar(three)
    assert pooled.shape == (3 * 32 * 32, 1, 1)
    assert groundtruth.pooled_exemplar(one) is one["front"]
    with pytest.raises(ParameterError, match="1 or 3"):
        groundtruth.exemplar_slices(real, 2)
    with pytest.raises(ParameterError, match="middle slice"):
        groundtruth.exemplar_slices(real, 3, 0, 4)
    with pytest.raises(ParameterError, match="--slice-index"):
        STUDIES["groundtruth"].runs("quick", reference=str(blobs), slices=3, slice_index=4)


def test_ground_truth_study_with_three_slices_hands_each_method_the_three(tmp_path, blobs, monkeypatch):
    specs = STUDIES["groundtruth"].runs("quick", reference=str(blobs), slices=3)
    assert {s.exemplar for s in specs} == {"blobs.three_slices"} and {s.slices for s in specs} == {3}
    seen = {}
    kopf = execute.METHODS["kopf"]

    def spy(exemplar=None, **kwargs):
        seen.update(kwargs.get("exemplars") or {})
        return kopf.synthesize(exemplar, **kwargs)

    monkeypatch.setitem(execute.METHODS, "kopf", dataclasses.replace(kopf, synthesize=spy))
    spec = next(s for s in specs if s.algorithm == "kopf")
    row = execute.execute_run(spec, str(tmp_path))
    assert row["status"] == "done", row
    real = groundtruth.load_reference(blobs)
    for view, plane in groundtruth.reference_slices(real).items():
        np.testing.assert_array_equal(seen[view], plane)
    control = next(s for s in specs if s.algorithm == "control")
    volume, per_view, _ = execute._synthesise(control, groundtruth.pooled_exemplar(seen), real, seen)
    assert per_view["right"] is seen["right"] and volume.shape == (16, 16, 16, 1)
    outcome = run_study(STUDIES["groundtruth"], mode="quick", out=tmp_path / "three", scheduler="serial",
                        volume=blobs, slices=3, progress=False, echo=None)
    assert {r["status"] for r in outcome.rows} == {"done"}
    record = json.loads((tmp_path / "three" / "groundtruth" / "study.json").read_text())
    assert record["options"]["slices"] == 3
