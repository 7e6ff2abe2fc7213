"""Studies and the report check their input first: a bad grid is refused as a whole, with exit 2,
one line naming the first problem, and no folder left behind; a damaged results.csv is read
defensively and an existing report is not overwritten without --overwrite."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest

import npmrf3d.model.exemplar
from npmrf3d import cli
from npmrf3d.errors import ParameterError
from npmrf3d.studies import STUDIES, Method, Scale, Study, run_study

TINY = Scale(exemplars=("gravel64",), seeds=(0,), sizes=(8,), levels=1, crop=24,
             common=(("window", 3), ("max_sweeps", 2)))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def _study(tmp_path, capsys, *args) -> str:
    out = tmp_path / "out"
    code = cli.main(["study", *args, "--out", str(out), "--scheduler", "serial", "--quiet"])
    line = _one_error_line(capsys)
    assert code == 2, line
    assert not out.exists()
    return line


@pytest.fixture()
def volume(tmp_path):
    path = tmp_path / "v.npy"
    np.save(path, (np.arange(16 ** 3).reshape(16, 16, 16) % 3).astype(np.float32))
    return path


def test_an_unknown_exemplar_is_refused_before_any_run(tmp_path, capsys):
    line = _study(tmp_path, capsys, "heuristics", "--quick", "--exemplars", "nosuch")
    assert line.startswith("npmrf3d: error: study heuristics: unknown exemplar 'nosuch'")


def test_a_missing_exemplar_file_is_refused(tmp_path, capsys):
    line = _study(tmp_path, capsys, "views", "--quick", "--exemplars", "gravel64", "nope.png")
    assert "study views: exemplar file 'nope.png' does not exist" in line


def test_a_size_too_small_for_the_windows_and_levels_names_the_run(tmp_path, capsys):
    line = _study(tmp_path, capsys, "heuristics", "--quick", "--size", "8", "--levels", "3")
    assert "study heuristics: run gravel64-ML_H1a-s0: size 8 is too small for window 3" in line
    line = _study(tmp_path, capsys, "heuristics", "--quick", "--size", "7", "--levels", "2")
    assert "study heuristics: run gravel64-ML_H1a-s0: size 7 is not divisible" in line


def test_a_slice_index_past_the_volume_is_refused(tmp_path, capsys, volume):
    line = _study(tmp_path, capsys, "groundtruth", "--quick", "--volume", str(volume),
                  "--slice-index", "999")
    assert "study groundtruth: --slice-index 999 is past the volume" in line
    assert "16 slices across axis 0" in line


def test_a_volume_with_nan_is_refused(tmp_path, capsys):
    path = tmp_path / "nan.npy"
    data = np.zeros((16, 16, 16), np.float32)
    data[1, 2, 3] = np.nan
    np.save(path, data)
    line = _study(tmp_path, capsys, "groundtruth", "--quick", "--volume", str(path))
    assert "study groundtruth: volume file" in line and "1 NaN or Inf values" in line


def test_a_volume_that_is_not_3d_is_refused(tmp_path, capsys):
    path = tmp_path / "flat.npy"
    np.save(path, np.zeros((16, 16), np.float32))
    line = _study(tmp_path, capsys, "groundtruth", "--quick", "--volume", str(path))
    assert "study groundtruth: volume file" in line and "(N1, N2, N3)" in line


def test_too_many_workers_leave_no_folder(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["study", "heuristics", "--quick", "--workers", "64", "--out", str(out)]) == 2
    assert "exceed" in _one_error_line(capsys)
    assert not out.exists()


def test_an_unknown_etr_exemplar_lists_the_installed_ones(tmp_path, capsys, monkeypatch):
    import imageio.v3 as iio

    folder = tmp_path / "terrains"
    folder.mkdir()
    iio.imwrite(folder / "snow.png", np.full((32, 32, 3), 200, np.uint8))
    monkeypatch.setattr(npmrf3d.model.exemplar, "ETR_DIR", folder)
    line = _study(tmp_path, capsys, "heuristics", "--quick", "--exemplars", "etr:nosuch")
    assert "unknown etr: exemplar 'etr:nosuch'" in line and "etr:snow" in line
    assert "does not exist" not in line
    out = tmp_path / "synth"
    assert cli.main(["synth", "etr:nosuch", "--size", "8", "--levels", "1", "--window", "3",
                     "--out", str(out)]) == 2
    line = _one_error_line(capsys)
    assert "unknown etr: exemplar 'etr:nosuch'" in line and "etr:snow" in line
    assert not out.exists()


def test_an_etr_exemplar_without_the_package_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(npmrf3d.model.exemplar, "ETR_DIR", tmp_path / "missing")
    line = _study(tmp_path, capsys, "heuristics", "--quick", "--exemplars", "etr:snow")
    assert "apt-get install extremetuxracer-data" in line


def test_a_bad_option_of_a_declared_method_names_the_run(tmp_path):
    study = Study(name="declared", title="t", question="?", full=TINY, quick=TINY,
                  methods=(Method("ok", params=(("heuristic", "ML_H2b"),)),
                           Method("odd", params=(("window", 4),)),
                           Method("typo", params=(("windw", 3),))))
    with pytest.raises(ParameterError, match="study declared: run gravel64-odd-s0: window must be an odd"):
        run_study(study, out=tmp_path, scheduler="serial", progress=False, echo=None)
    assert not (tmp_path / "declared").exists()
    typo = Study(name="typo", title="t", question="?", full=TINY, quick=TINY,
                 methods=(Method("typo", params=(("windw", 3),)),))
    with pytest.raises(ParameterError, match="study typo: run gravel64-typo-s0: method npmrf has no option 'windw'"):
        run_study(typo, out=tmp_path, scheduler="serial", progress=False, echo=None)
    real = Study(name="nothing-real", title="t", question="?", full=TINY, quick=TINY,
                 methods=(Method("real", "real"),))
    with pytest.raises(ParameterError, match="run gravel64-real-s0: method 'real' is a crop of the real volume"):
        run_study(real, out=tmp_path, scheduler="serial", progress=False, echo=None)
    assert not any(tmp_path.iterdir())


def test_every_quick_study_passes_the_check(tmp_path, volume):
    from npmrf3d.studies.inputs import check_reference, check_runs
    from npmrf3d.studies.runner import leave_out_unavailable

    for name, study in STUDIES.items():
        kw = {}
        real = None
        if study.needs_volume:
            kw["reference"] = str(volume)
            real = check_reference(name, volume)
        specs, _ = leave_out_unavailable(study.runs("quick", **kw))
        check_runs(name, specs, real)


# --------------------------------------------------------------------------- report


def _results(tmp_path, rows, columns=None) -> object:
    study_dir = tmp_path / "res" / "demo"
    study_dir.mkdir(parents=True)
    columns = columns or list(rows[0])
    with open(study_dir / "results.csv", "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    return study_dir


ROW = {"study": "demo", "run_id": "e-m-s0", "exemplar": "e", "method": "m", "algorithm": "npmrf",
       "seed": "0", "size": "8", "levels": "1", "status": "done", "seconds": "1.5",
       "mean_histogram_kl": "0.25", "mean_autocorrelation_l2": "0.5"}


def test_report_shows_a_cell_that_is_not_a_number_as_missing_and_says_where(tmp_path, capsys):
    rows = [dict(ROW), dict(ROW, run_id="e-m-s1", seed="1")]
    rows[0]["mean_histogram_kl"] = "garbage"
    rows[1]["mean_autocorrelation_l2"] = "nan"
    study_dir = _results(tmp_path, rows)
    assert cli.main(["report", str(study_dir)]) == 0
    captured = capsys.readouterr()
    warnings = [line for line in captured.err.splitlines() if line.strip()]
    assert len(warnings) == 2, captured.err
    csv_path = study_dir / "results.csv"
    assert warnings[0] == (f"npmrf3d report: warning: {csv_path}: row 1 (e-m-s0), column "
                           f"mean_histogram_kl: 'garbage' is not a number; shown as missing")
    assert "row 2 (e-m-s1), column mean_autocorrelation_l2: 'nan'" in warnings[1]
    text = (study_dir / "report.html").read_text(encoding="utf-8")
    assert "garbage" not in text and ">nan<" not in text


def test_report_refuses_a_results_file_without_its_columns(tmp_path, capsys):
    rows = [{"run_id": "a", "method": "m", "mean_kl": "1"}]
    study_dir = _results(tmp_path, rows)
    assert cli.main(["report", str(study_dir)]) == 2
    line = _one_error_line(capsys)
    assert f"results file '{study_dir / 'results.csv'}' lacks the columns exemplar, seed, size, levels, status" in line
    assert not (study_dir / "report.html").exists()


def test_report_does_not_overwrite_without_overwrite(tmp_path, capsys):
    study_dir = _results(tmp_path, [dict(ROW)])
    target = tmp_path / "page.html"
    target.write_text("mine", encoding="utf-8")
    assert cli.main(["report", str(study_dir), "--out", str(target)]) == 2
    assert "already exists; pass --overwrite" in _one_error_line(capsys)
    assert target.read_text(encoding="utf-8") == "mine"
    assert cli.main(["report", str(study_dir), "--out", str(target), "--overwrite"]) == 0
    assert target.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


# --------------------------------------------------------------------------- Ctrl-C


_INTERRUPTED_STUDY = """
import os
import signal
import sys
import time

from npmrf3d import cli
from npmrf3d.studies import runner

real = runner.execute_run


def interrupt_during_the_runs(spec, study_dir, threads=None):
    # on a worker: the parent's Ctrl-C, sent to the whole process group as a terminal does
    os.killpg(os.getpgid(os.getppid()), signal.SIGINT)
    time.sleep(30)


if __name__ == "__main__":
    runner.execute_run = interrupt_during_the_runs
    sys.exit(cli.main(["study", "heuristics", "--quick", "--out", sys.argv[1], "--workers", "1",
                       "--threads", "1", "--quiet"]))
"""


def test_ctrl_c_on_a_local_cluster_says_one_line(tmp_path):
    script = tmp_path / "interrupted.py"
    script.write_text(_INTERRUPTED_STUDY)
    done = subprocess.run([sys.executable, str(script), str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=240, cwd=tmp_path,
                          start_new_session=True)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 130, done.stderr[-3000:]
    assert lines == ["npmrf3d: interrupted"], done.stderr[-3000:]
