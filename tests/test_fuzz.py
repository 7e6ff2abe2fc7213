"""Fuzzing with hypothesis: for any exemplar (shape, dtype incl. bool/complex/float16, NaN/Inf,
1-8 channels), window/levels/size combination, truncated or non-image file, path with spaces or
non-ASCII characters, the API returns a valid result or raises ParameterError (never an
IndexError, a numba error or a hang), and the command line exits 0 or 2 with one line.

Bounded for CI (``HYPOTHESIS_PROFILE=ci``, the default: about 20 s); ``HYPOTHESIS_PROFILE=long``
runs many more examples locally.
"""

from __future__ import annotations

import os
import pathlib
import tempfile

import imageio.v3 as iio
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import npmrf3d
from npmrf3d import cli
from npmrf3d.errors import ParameterError
from npmrf3d.methods.kopf import kopf_synthesize

settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.register_profile("long", max_examples=500, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")

DTYPES = ["bool", "uint8", "uint16", "int64", "float16", "float32", "float64", "complex64"]


@st.composite
def exemplars(draw):
    dtype = np.dtype(draw(st.sampled_from(DTYPES)))
    ndim = draw(st.sampled_from([1, 2, 2, 3, 3, 3, 4]))
    side = st.one_of(st.integers(6, 14), st.integers(6, 14), st.integers(0 if ndim == 1 else 1, 5))
    shape = [draw(side) for _ in range(min(ndim, 2))]
    if ndim >= 3:
        shape.append(draw(st.integers(1, 8)))
    if ndim == 4:
        shape.append(2)
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    values = rng.integers(0, 4, size=shape)
    array = values.astype(dtype) if dtype.kind != "b" else values > 1
    special = draw(st.sampled_from([None, None, np.nan, np.inf, -np.inf]))
    if special is not None and dtype.kind in "fc" and array.size:
        array.flat[draw(st.integers(0, array.size - 1))] = special
    return array


def _valid_volume(result, size):
    volume = result.volume
    assert volume.dtype == np.float32 and volume.ndim == 4
    assert volume.shape[:3] == (size, size, size) and np.isfinite(volume).all()


@settings.get_profile(PROFILE)
@given(array=exemplars(), window=st.sampled_from([3, 3, 3, 5, 1, 4, 9]),
       levels=st.sampled_from([1, 1, 2, 2, 0, 3]), size=st.sampled_from([4, 8, 8, 6, 3, 0, -1]),
       anneal=st.booleans())
def test_synthesize_returns_a_volume_or_a_parameter_error(array, window, levels, size, anneal):
    try:
        result = npmrf3d.synthesize(array, size=size, window=window, levels=levels, rng=0,
                                    max_sweeps=1, proposals=1,
                                    relaxation="anneal" if anneal else "icm")
    except ParameterError:
        return
    _valid_volume(result, size)


@settings.get_profile(PROFILE)
@given(array=exemplars(), window=st.sampled_from([2, 3, 4, 4, 1, 6]),
       levels=st.sampled_from([1, 1, 2, 0]), size=st.sampled_from([4, 8, 8, 6, 0, -1]),
       grid=st.sampled_from([1, 2, 2, 0, 3]))
def test_kopf_returns_a_volume_or_a_parameter_error(array, window, levels, size, grid):
    try:
        result = kopf_synthesize(array, size=size, window=window, levels=levels, grid=grid,
                                 iterations=1, rng=0)
    except ParameterError:
        return
    _valid_volume(result, size)


NAMES = st.text(alphabet=st.sampled_from(list("ab ü漢é-_.")), min_size=1, max_size=8)


@settings.get_profile(PROFILE)
@given(name=NAMES, suffix=st.sampled_from([".png", ".npy", ".tif", ".jpg", ".txt", ""]),
       cut=st.floats(0.0, 1.0), kind=st.sampled_from(["png", "npy", "tif", "text", "empty"]))
def test_truncated_or_foreign_files_load_or_raise_parameter_error(name, suffix, cut, kind):
    with tempfile.TemporaryDirectory(prefix="fuzz dir ü ") as folder:
        path = pathlib.Path(folder) / f"{name.strip('.') or 'x'}{suffix}"
        image = np.random.default_rng(0).integers(0, 256, (12, 12), dtype=np.uint8)
        if kind == "png":
            iio.imwrite(path.with_suffix(".tmp.png"), image)
            data = path.with_suffix(".tmp.png").read_bytes()
        elif kind == "tif":
            import tifffile
            tifffile.imwrite(path.with_suffix(".tmp.tif"), image)
            data = path.with_suffix(".tmp.tif").read_bytes()
        elif kind == "npy":
            np.save(path.with_suffix(".tmp.npy"), image)
            data = path.with_suffix(".tmp.npy").read_bytes()
        else:
            data = "not an image ü".encode() if kind == "text" else b""
        path.write_bytes(data[: int(len(data) * cut)])
        try:
            array = npmrf3d.load_exemplar(path)
        except ParameterError:
            return
        assert array.dtype == np.float32 and array.ndim == 3 and np.isfinite(array).all()


OPTION_TEXT = st.one_of(st.integers(-5, 40).map(str), st.sampled_from(
    ["", "x", "3.5", "nan", "inf", "-0", "1e3", "8,8", "8,8,8", "16,16,16,16", " 8", "0x10", "٣"]))


@settings.get_profile(PROFILE)
@given(size=OPTION_TEXT, window=OPTION_TEXT, levels=OPTION_TEXT, kopf=st.booleans(),
       name=NAMES)
def test_cli_dry_run_exits_0_or_2_with_one_line_and_writes_nothing(size, window, levels, kopf,
                                                                     name, capsys):
    with tempfile.TemporaryDirectory(prefix="fuzz cli ü ") as folder:
        command = ["baseline", "kopf"] if kopf else ["synth"]
        out = pathlib.Path(folder) / name
        argv = [*command, "--dry-run", "--size", size, "--window", window, "--levels", levels,
                "--out", str(out)]
        code = cli.main([a for a in argv])
        captured = capsys.readouterr()
        assert code in (0, 2), (argv, code, captured.err)
        if code == 2:
            lines = captured.err.strip().splitlines()
            assert len(lines) == 1 and ": error: " in lines[0] and "Traceback" not in captured.err
        else:
            assert "needs about" in captured.out
        assert list(pathlib.Path(folder).iterdir()) == []
