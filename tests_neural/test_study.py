"""The ``neural`` method in the npk study (with torch): it runs, and its training and generation
are timed apart in results.csv and run.json."""

from __future__ import annotations

import json

import numpy as np

from npmrf3d.studies import STUDIES, catalog, run_study, table


def test_the_npk_study_runs_the_neural_method(tmp_path):
    npk = STUDIES["npk"]
    declared = {m.name: m for m in npk.quick.methods}
    assert declared["neural"] is catalog._QUICK_NEURAL
    study = npk.with_scale("quick", methods=(declared["neural"], declared["control"]))
    messages = []
    outcome = run_study(study, mode="quick", out=tmp_path, scheduler="serial", threads=1,
                        progress=False, echo=messages.append)
    assert outcome.counts == {"done": 2, "skipped": 0, "failed": 0}
    assert not any(m.startswith("left out") for m in messages)
    study_dir = tmp_path / "npk"
    info = json.loads((study_dir / "study.json").read_text())
    assert info["left_out"] == []
    assert [r["method"] for r in info["runs"]] == ["neural", "control"]

    rows = table.read_results(study_dir / "results.csv")
    columns = list(rows[0])
    assert columns[columns.index("seconds") + 1:columns.index("seconds") + 3] == ["train_seconds",
                                                                                   "generate_seconds"]
    neural, control = rows
    assert neural["method"] == "neural" and neural["status"] == "done"
    train, generate, total = (float(neural[c]) for c in ("train_seconds", "generate_seconds", "seconds"))
    assert 0 < train < total and 0 < generate < total and train + generate <= total
    assert control["train_seconds"] == "" and control["generate_seconds"] == ""
    assert np.isfinite(float(neural["mean_histogram_kl"]))

    record = json.loads((study_dir / neural["run_id"] / "run.json").read_text())
    assert set(record["timings"]) == {"train", "generate", "total"}
    assert record["spec"]["params"]["iterations"] == 3
    volume = np.load(study_dir / neural["run_id"] / "volume.npy")
    assert volume.shape == (8, 8, 8, 1) and volume.std() > 0
    again = run_study(study, mode="quick", out=tmp_path, scheduler="serial", threads=1,
                      progress=False, echo=None)
    assert [r["status"] for r in again.rows] == ["skipped", "skipped"]
    assert again.rows[0]["train_seconds"] == train  # read back from run.json
