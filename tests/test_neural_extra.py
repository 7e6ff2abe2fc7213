"""The neural method without its extra: ``import npmrf3d`` never imports torch, and a neural
command or call without torch stops with one clear line.

Torch is hidden with ``sys.modules["torch"] = None`` (an import then fails as if it were not
installed), so these tests behave the same whether or not the extra is installed. The neural
method's own tests need torch and live in ``tests_neural/`` (``.ci/run`` runs them).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from npmrf3d.cli.main import main
from npmrf3d.errors import ParameterError
from npmrf3d.methods import METHODS, neural
from npmrf3d.methods.neural import MissingExtraError


@pytest.fixture
def no_torch(monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)


def test_importing_the_package_and_its_cli_imports_no_torch():
    code = ("import sys, npmrf3d, npmrf3d.cli.main, npmrf3d.methods; "
            "print('torch' in sys.modules, 'npmrf3d.methods.neural.engine' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


@pytest.mark.parametrize("argv", [
    ["neural", "train", "--iterations", "2"],
    ["neural", "generate", "model.pt", "--size", "16"],
])
def test_neural_commands_without_torch_are_one_line(no_torch, tmp_path, capsys, argv):
    out = tmp_path / ("m.pt" if argv[1] == "train" else "v.npy")
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert 'needs torch, which is not installed' in err
    assert 'pip install "npmrf3d[neural]"' in err
    assert not out.exists()


def test_the_api_and_the_registry_without_torch_raise_the_extra_error(no_torch, tiny_grey):
    with pytest.raises(MissingExtraError, match=r"training the neural generator needs torch"):
        neural.train(tiny_grey, iterations=1)
    method = METHODS["neural"]
    config = method.make_config(size=8, iterations=1)
    with pytest.raises(MissingExtraError, match=r"npmrf3d\[neural\]"):
        method.run({"front": tiny_grey.astype(np.float32)[..., None]}, config, np.random.default_rng(0))
    assert issubclass(MissingExtraError, ParameterError)


def test_the_config_validates_without_torch(no_torch):
    assert method_defaults() == (64, 64, 64)
    with pytest.raises(ParameterError, match="iterations must be between 1 and 10000000; got 0"):
        neural.make_neural_config(iterations=0)


def method_defaults():
    return METHODS["neural"].make_config().size
