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


def test_first_compile_is_announced_once_and_only_without_cached_code(
    tmp_path, monkeypatch, caplog
):
    """The kernels' first compile is a silent minute: one line says so, when the cache holds
    no compiled code of the module, once per process."""
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    monkeypatch.setattr(numba_setup, "_AHEAD", {})  # none started ahead by an earlier job
    caplog.set_level(logging.INFO, logger=numba_setup.__name__)
    module = "tactile_exp.models.grouped_conv_numba"
    numba_setup.announce_compile(module)
    numba_setup.announce_compile(module)
    assert [r.getMessage().split(" (")[0] for r in caplog.records] == [
        "compiling the grouped_conv_numba kernels"
    ]
    caplog.clear()
    (tmp_path / "models_abc").mkdir()
    (tmp_path / "models_abc" / "grouped_conv_numba.stack_forward-1.py311.nbi").touch()
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    numba_setup.announce_compile(module)
    assert caplog.records == []


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
    numba_setup.announce_compile("toy_kernels")
    assert process.returncode == 0 and "toy_kernels" not in numba_setup._AHEAD
    assert int((tmp_path / "pid").read_text()) != os.getpid()
    assert numba_setup._cached("toy_kernels")
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0].startswith("compiling the toy_kernels kernels ahead")
    assert not any(m.startswith("compiling the toy_kernels kernels (") for m in messages)
    numba_setup.compile_ahead(["toy_kernels"])  # cached now: nothing started
    assert numba_setup._AHEAD == {}


def test_a_failed_compile_ahead_leaves_the_compile_to_the_first_call(tmp_path, monkeypatch, caplog):
    (tmp_path / "toy_failing.py").write_text(TOY_KERNELS.replace("cache=True", "cache=False"))
    _importable(tmp_path, monkeypatch)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(numba_setup.numba.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("TOY_MARK", str(tmp_path / "pid"))
    monkeypatch.setenv("TOY_FAIL", "1")
    monkeypatch.setattr(numba_setup, "_CHECKED", set())
    monkeypatch.setattr(numba_setup, "_AHEAD", {})
    caplog.set_level(logging.INFO, logger=numba_setup.__name__)
    numba_setup.compile_ahead(["toy_failing"])
    process = numba_setup._AHEAD["toy_failing"]
    numba_setup.announce_compile("toy_failing")
    assert process.returncode != 0
    assert caplog.records[-1].getMessage().startswith("compiling the toy_failing kernels (")


def test_check_rows_refuses_rows_outside_the_input_and_takes_the_rest():
    for rows in (torch.tensor([0, 4, 2]), np.array([3]), torch.tensor([], dtype=torch.int64)):
        numba_setup.check_rows(rows, 5, "kernel")
    for rows in (torch.tensor([0, 5]), np.array([-1, 2])):
        with pytest.raises(IndexError, match=r"^kernel: rows must lie in \[0, 5\), the rows of"):
            numba_setup.check_rows(rows, 5, "kernel")
