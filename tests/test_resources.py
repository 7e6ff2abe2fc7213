"""The up-front resource check (npmrf3d.resources, the registry's ``resources`` hooks, --dry-run).

The memory estimate of each registered method, less the process's own runtime part, is compared
with the peak that ``tracemalloc`` measures on small runs (within a factor of 2); the whole
estimate of the default ``synth`` against measured peak RSS is ``benchmarks/bench_memory_estimate.py``; absurd sizes are refused in well under a second
with one line and exit code 2, nothing written.
"""

from __future__ import annotations

import itertools
import pathlib
import subprocess
import sys
import time
import tracemalloc

import numpy as np
import pytest

from npmrf3d import cli, resources
from npmrf3d.config import SynthesisMethod
from npmrf3d.methods import METHODS, check_resources, estimate, get_method
from npmrf3d.model.exemplar import resolve_exemplars
from npmrf3d.resources import ResourceError

SMALL = np.random.default_rng(1).integers(0, 4, (12, 12)).astype(np.uint8) * 80

#: (method, exemplar, configuration): small runs where the volume dominates and where the
#: exemplar patch tables dominate.
CASES = [
    ("npmrf", "small", dict(size=32, levels=1, window=3, support="full", max_sweeps=1)),
    ("npmrf", "small", dict(size=16, levels=2, window=3)),
    ("npmrf", "tiny_rgb", dict(size=8, levels=1, window=5, relaxation="anneal", support="full", proposals=1)),
    ("kopf", "small", dict(size=32, levels=1, window=4, iterations=1)),
    ("kopf", "tiny_rgb", dict(size=16, levels=2, window=4, iterations=1)),
]


def _per_view(name, exemplar, kwargs):
    method = get_method(name)
    config = method.make_config(**kwargs)
    return method, config, resolve_exemplars(exemplar, None, config.views, **method.fit(config))


@pytest.mark.parametrize("name, which, kwargs", CASES)
def test_estimate_within_factor_two_of_measured_peak(name, which, kwargs, tiny_rgb):
    exemplar = SMALL if which == "small" else tiny_rgb
    method, config, per_view = _per_view(name, exemplar, kwargs)
    method.run(per_view, config, np.random.default_rng(0))  # compile and warm up
    tracemalloc.start()
    try:
        method.run(per_view, config, np.random.default_rng(0))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    needed = estimate(method, config, per_view)
    # tracemalloc sees the arrays, not the interpreter and libraries that the runtime part counts
    arrays = needed.bytes - needed.parts.get("runtime", 0)
    assert 0.5 <= arrays / peak <= 2.0, (name, kwargs, arrays, peak)


def test_every_registered_method_has_a_resources_hook():
    for method in METHODS.values():
        assert method.resources is not None, method.name


def test_a_new_method_registers_its_own_hook_or_gets_the_generic_one(tiny_rgb):
    _, config, per_view = _per_view("npmrf", tiny_rgb, dict(size=8, levels=1, window=3))
    base = get_method("npmrf")
    fields = dict(name="new", run=base.run, make_config=base.make_config,
                  config_class=base.config_class, synthesize=base.synthesize, fit=base.fit)
    plain = SynthesisMethod(**fields)
    assert estimate(plain, config, per_view).bytes == 2 * 8 ** 3 * 3 * 4
    hooked = SynthesisMethod(**fields, resources=lambda c, ex: resources.Estimate({"volume": 10 ** 15}))
    with pytest.raises(ResourceError, match="are available"):
        check_resources(hooked, config, per_view, available=10 ** 9)


def test_check_memory_names_the_figure_and_the_limit():
    with pytest.raises(ResourceError) as info:
        resources.check_memory(resources.Estimate({"volume": 3 * 2**30, "work arrays": 2**30}),
                               available=2**30)
    text = str(info.value)
    assert "4 GiB" in text and "1 GiB are available" in text and "volume" in text
    resources.check_memory(resources.Estimate({"volume": 10}), available=100)  # fits: silent


def test_available_memory_is_positive():
    assert resources.available_memory() > 0


def test_format():
    assert resources.format_bytes(1536) == "1.5 KiB"
    assert resources.format_bytes(271 * 2**30) == "271 GiB"
    assert resources.format_seconds(30) == "30 s"


@pytest.mark.parametrize("argv", [
    ["synth", "--size", "4096"], ["synth", "--size", "100000"],
    ["synth", "--size", "2048,2048,4096", "--levels", "1"],
    ["baseline", "kopf", "--size", "4096"], ["baseline", "kopf", "--size", "100000", "--levels", "1"],
])
def test_absurd_sizes_refused_before_anything_is_allocated(argv, tmp_path, capsys):
    # refused from the estimate, not after trying: the process's own CPU time (which a busy
    # machine does not inflate as it does the wall time) stays far below what allocating or
    # filling even one such volume would take
    out = tmp_path / "out"
    t0 = time.process_time()
    code = cli.main([*argv, "--out", str(out)])
    used = time.process_time() - t0
    err = capsys.readouterr().err
    assert code == 2 and used < 2.0, used
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "of memory" in lines[0] and "are available" in lines[0], err
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("size", ["4096", "100000"])
def test_absurd_size_subprocess(size, tmp_path):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "npmrf3d", "synth", "--size", size, "--out", "o"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60)
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
    assert "npmrf3d: error: this run needs about" in proc.stderr
    assert list(pathlib.Path(tmp_path).iterdir()) == []
    assert elapsed < 30  # import time included; the check itself is timed in-process above


def test_api_refuses_too(tiny_rgb):
    from npmrf3d import synthesize
    from npmrf3d.methods.kopf import kopf_synthesize
    with pytest.raises(ResourceError):
        synthesize(tiny_rgb, size=65536, levels=1, window=3)
    with pytest.raises(ResourceError):
        kopf_synthesize(tiny_rgb, size=65536, levels=1, window=4)


@pytest.mark.parametrize("argv", [["synth"], ["baseline", "kopf"], ["synth", "--size", "4096"]])
def test_dry_run_prints_the_estimate_and_writes_nothing(argv, tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main([*argv, "--dry-run", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "needs about" in text and "available memory" in text and "on 2 cores" in text
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_coherent_estimate_grows_with_the_exemplar():
    method = get_method("npmrf")
    config = method.make_config(size=8, levels=1, window=3)
    sides = (64, 256, 1024, 4096)
    needs = [estimate(method, config, {v: (s, s, 3) for v in config.views}) for s in sides]
    tables = [e.parts["exemplar patch tables"] for e in needs]
    assert all(b > a for a, b in itertools.pairwise(tables))
    # per patch, about 4x the bytes for a side twice as long: the patches, not a constant
    assert 14 < tables[-1] / tables[-2] < 18
    assert all(b.seconds > a.seconds for a, b in itertools.pairwise(needs))
    assert needs[0].parts["runtime"] == resources.RUNTIME_BYTES
    with pytest.raises(ResourceError, match="exemplar patch tables"):
        resources.check_memory(needs[-1], available=needs[-2].bytes)


def test_coherent_estimate_of_a_patch_counts_its_arrays():
    # 3x3 grey patches: 9 float32 values, then the PCA's two float64 copies and projection
    assert resources.coherent_patch_bytes(3, 1) == 4 * 9 + max(16 * 9 + 8 * 9, 4 * 8 * 9 + 56 + 16 * 6 + 20 * 5)
    assert resources.coherent_patch_bytes(7, 3) > resources.coherent_patch_bytes(7, 1)
    assert resources.coherent_patch_bytes(3, 1, exclude=2.0) > resources.coherent_patch_bytes(3, 1)
