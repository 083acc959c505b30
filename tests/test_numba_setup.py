"""numba's settings for every kernel module (cache folder, threading layer) and the compile
ahead: the kernels a job runs compiled in a background process while it loads its data; the
kernels' row check."""

import logging
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from tactile_exp.models import numba_setup


def test_numba_cache_goes_to_the_user_cache_folder(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["TACTILE_EXP_CACHE"] = str(tmp_path)
    code = "import tactile_exp.models.grouped_conv_numba, numba; print(numba.config.CACHE_DIR)"
    lines = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert lines[0] == str(tmp_path / "numba")


def test_threading_layer_is_workqueue_even_with_a_given_numba_cache_dir(tmp_path):
    """numba imported before ``numba_setup`` (any ``from numba import ...``) once kept its
    default threading layer whenever $NUMBA_CACHE_DIR was set, as in this test suite."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    code = (
        "import numba; import tactile_exp.models.grouped_conv_numba; "
        "print(numba.config.THREADING_LAYER, numba.config.CACHE_DIR)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["workqueue", str(tmp_path)]


TOY_KERNELS = """
import os
from tactile_exp.models.numba_setup import numba


@numba.njit(cache=True)
def twice(x):
    return 2 * x


def warm_up():
    with open(os.environ["TOY_MARK"], "w") as f:
        f.write(str(os.getpid()))
    twice(1.0)
    if os.environ.get("TOY_FAIL"):
        raise RuntimeError("toy compile failed")
"""


def _importable(folder, monkeypatch) -> None:
    """Modules in ``folder`` importable here and in a new interpreter."""
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(folder), *sys.path]))


def test_a_cold_module_is_compiled_in_another_process_and_announced_once(
    tmp_path, monkeypatch, caplog
):
    """Without a compile ahead, the first call has the kernels compiled in another process (its
    own pid) and waits: one line says so, once per process; a module the cache holds starts
    nothing and says nothing."""
    (tmp_path / "toy_kernels.py").write_text(TOY_KERNELS)
    _importable(tmp_path, monkeypatch)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)  # the other process gets numba's folder
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("TOY_MARK", str(tmp_path / "pid"))
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    monkeypatch.setattr(numba_setup, "_AHEAD", {})
    caplog.set_level(logging.INFO, logger=numba_setup.__name__)
    numba_setup.ensure_compiled("toy_kernels")
    numba_setup.ensure_compiled("toy_kernels")
    assert int((tmp_path / "pid").read_text()) != os.getpid()
    assert numba_setup._cached("toy_kernels")
    assert [r.getMessage().split(" (")[0] for r in caplog.records] == [
        "compiling the toy_kernels kernels"
    ]
    caplog.clear()
    (tmp_path / "pid").unlink()
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    numba_setup.ensure_compiled("toy_kernels")
    assert caplog.records == [] and not (tmp_path / "pid").exists()


def test_compiles_started_together_compile_a_module_once(tmp_path, monkeypatch):
    """Two compile processes for the same kernels on one cache (jobs side by side, a test run's
    workers): the second waits for the first's compile and finds them cached."""
    (tmp_path / "toy_kernels.py").write_text(
        TOY_KERNELS.replace('"w"', '"a"').replace("str(os.getpid())", "f'{os.getpid()} '")
    )  # each compile appends its pid
    _importable(tmp_path, monkeypatch)
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("TOY_MARK", str(tmp_path / "pids"))
    both = [numba_setup._compile_elsewhere(["toy_kernels"]) for _ in range(2)]
    assert [process.wait() for process in both] == [0, 0]
    assert len((tmp_path / "pids").read_text().split()) == 1
    assert numba_setup._cached("toy_kernels")


def test_compile_ahead_fills_the_cache_from_another_process_and_the_first_call_waits(
    tmp_path, monkeypatch, caplog
):
    """A cold module is compiled in a background process (its own pid); the first kernel call
    waits for it and finds the cache filled (no "compiling" line of its own); a warm module
    starts nothing."""
    (tmp_path / "toy_kernels.py").write_text(TOY_KERNELS)
    _importable(tmp_path, monkeypatch)
    cache = tmp_path / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(cache))
    monkeypatch.setenv("TOY_MARK", str(tmp_path / "pid"))
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    monkeypatch.setattr(numba_setup, "_AHEAD", {})
    caplog.set_level(logging.INFO, logger=numba_setup.__name__)
    numba_setup.compile_ahead(["toy_kernels", "toy_kernels"])
    process = numba_setup._AHEAD["toy_kernels"]
    numba_setup.ensure_compiled("toy_kernels")
    assert process.returncode == 0 and "toy_kernels" not in numba_setup._AHEAD
    assert int((tmp_path / "pid").read_text()) != os.getpid()
    assert numba_setup._cached("toy_kernels")
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0].startswith("compiling the toy_kernels kernels ahead")
    assert not any(m.startswith("compiling the toy_kernels kernels (") for m in messages)
    numba_setup.compile_ahead(["toy_kernels"])  # cached now: nothing started
    assert numba_setup._AHEAD == {}


@pytest.mark.parametrize("ahead", [True, False])
def test_a_failed_compile_elsewhere_leaves_the_compile_to_the_first_call(
    ahead, tmp_path, monkeypatch, caplog
):
    """The other process fails (ahead or started by the first call): the kernels compile in
    this one, with a warning that names the difference it can make."""
    (tmp_path / "toy_failing.py").write_text(TOY_KERNELS.replace("cache=True", "cache=False"))
    _importable(tmp_path, monkeypatch)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("TOY_MARK", str(tmp_path / "pid"))
    monkeypatch.setenv("TOY_FAIL", "1")
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    monkeypatch.setattr(numba_setup, "_AHEAD", {})
    caplog.set_level(logging.INFO, logger=numba_setup.__name__)
    if ahead:
        numba_setup.compile_ahead(["toy_failing"])
    numba_setup.ensure_compiled("toy_failing")
    assert int((tmp_path / "pid").read_text()) != os.getpid()  # it ran, elsewhere, and failed
    last = caplog.records[-1]
    assert last.levelname == "WARNING"
    assert last.getMessage().startswith("compiling the toy_failing kernels in this process")


LSTM_STEP = """
import numpy as np, torch
from tactile_exp.models.haptic_lstm import LSTMBody
from tactile_exp.models.lstm_kernels import lstm_step
torch.manual_seed(0)
x, y = torch.randn(90, 32, 30), (torch.rand(90) > 0.5).float()
body, out = LSTMBody(32, 10, impl="compiled"), torch.nn.Linear(10, 1)
lstm_step(x, torch.arange(90), y, body.lstm, body.fc, out, loss="logistic")
print([p.grad.numpy().tobytes().hex() for p in [*body.parameters(), *out.parameters()]])
"""


@pytest.mark.slow
def test_a_step_is_the_same_whether_its_kernels_were_compiled_before(tmp_path):
    """Two processes, the first with an empty numba cache (the kernels compiled then), the
    second loading them: the LSTM training step's gradients equal to the bit. (Compiled in the
    first process itself, its FC and output weight gradients differed in the last bits.)"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    first, second = (
        subprocess.run(
            [sys.executable, "-c", LSTM_STEP], env=env, capture_output=True, text=True, check=True
        ).stdout
        for _ in range(2)
    )
    assert first and first == second


def test_check_rows_refuses_rows_outside_the_input_and_takes_the_rest():
    for rows in (torch.tensor([0, 4, 2]), np.array([3]), torch.tensor([], dtype=torch.int64)):
        numba_setup.check_rows(rows, 5, "kernel")
    for rows in (torch.tensor([0, 5]), np.array([-1, 2])):
        with pytest.raises(IndexError, match=r"^kernel: rows must lie in \[0, 5\), the rows of"):
            numba_setup.check_rows(rows, 5, "kernel")
