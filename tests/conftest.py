"""Shared fixtures: a tiny generated data set, a temporary MLflow store, config composition."""

from __future__ import annotations

import copy
import os
import shutil
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

os.environ["MLFLOW_DISABLE_TELEMETRY"] = "true"

CONF = Path(__file__).resolve().parents[1] / "conf"
# A tiny PHAC-2 stand-in: all 60 objects (so every published split exists), 2 trials, short EPs.
TINY_DATA = [
    "data.trials=2",
    "data.duration_scale=0.1",
    "data.views=1",
    "data.image_width=96",
    "data.image_height=64",
]


def pytest_configure(config: pytest.Config) -> None:
    """In an xdist worker, torch's and BLAS's own threads on this worker's share of the cores:
    two workers with two threads each on two cores spent ~10% more CPU on the fast suite,
    waiting on each other's threads (tests that compare thread counts set theirs)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:
        import torch
        from threadpoolctl import threadpool_limits

        share = max(1, (os.cpu_count() or 1) // workers)
        torch.set_num_threads(share)
        threadpool_limits(share, user_api="blas")


def _shared_tmp(factory: pytest.TempPathFactory, name: str) -> Path:
    """A folder of this test run, shared by its xdist worker processes (each has its own basetemp
    under one parent), so kernels compile and tiny data is generated once, not once per worker."""
    base = factory.getbasetemp()
    path = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="session", autouse=True)
def numba_cache() -> Path:
    """The compiled-kernel cache every test uses (set before numba loads): the machine's, as
    jobs use it (``numba_setup``), so a test run loads what the README's job or an earlier run
    compiled instead of compiling every kernel again (numba recompiles a module whose source
    changed); ``$TACTILE_EXP_TEST_NUMBA_CACHE`` names another (CI: an empty one, so the fast
    suite compiles every kernel from scratch and the slow suite reuses them)."""
    from tactile_exp.data.phac2 import default_cache_dir

    kept = os.environ.get("TACTILE_EXP_TEST_NUMBA_CACHE") or os.environ.get("NUMBA_CACHE_DIR")
    path = Path(kept) if kept else default_cache_dir() / "numba"
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    return path


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Generated data and preprocessed arrays; ``$TACTILE_EXP_TEST_CACHE`` keeps them across
    sessions (mutation testing runs pytest once per mutant; entries are keyed by content)."""
    kept = os.environ.get("TACTILE_EXP_TEST_CACHE")
    return Path(kept) if kept else _shared_tmp(tmp_path_factory, "cache")


@pytest.fixture(scope="session")
def mlflow_template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty MLflow sqlite store, made once for the test run (every worker copies it):
    creating the schema costs ~1.5 s per file."""
    from mlflow.tracking import MlflowClient

    path = _shared_tmp(tmp_path_factory, "mlflow-template") / "mlflow.db"
    if not path.exists():  # made under another name, then renamed: a worker sees it whole
        made = path.with_name(f"making-{os.getpid()}.db")
        MlflowClient(f"sqlite:///{made}").search_experiments()  # creates the schema
        os.replace(made, path)
    return path


@pytest.fixture
def mlflow_uri(mlflow_template: Path, tmp_path: Path) -> str:
    """Each test's own MLflow store (a copy of the empty template), artifacts beside it."""
    path = tmp_path / "mlflow" / "mlflow.db"
    path.parent.mkdir()
    shutil.copy(mlflow_template, path)
    return f"sqlite:///{path}"


@pytest.fixture(scope="session")
def compose_config():
    """compose(overrides) -> resolved-ready DictConfig, as Hydra would build it. The same
    overrides are composed once per test process (~0.1 s a compose; many tests compose the
    same groups) and each call gets its own copy, which it may change: interpolations such as
    ``${oc.env:...}`` stay unresolved until read, as in a fresh compose."""
    composed: dict[tuple[str, ...], DictConfig] = {}

    def _compose(overrides: list[str] | None = None) -> DictConfig:
        key = tuple(overrides or [])
        if key not in composed:
            with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
                composed[key] = compose("config", overrides=list(key), return_hydra_config=False)
        return copy.deepcopy(composed[key])

    return _compose


@pytest.fixture
def tiny_config(compose_config, cache_dir: Path, mlflow_uri: str):
    """compose with tiny data, a temporary cache, this test's MLflow store and the tiny schedule
    (few epochs: these tests check the plumbing, not the paper's numbers)."""

    def _tiny(overrides: list[str] | None = None, adjectives: str = "[hard,soft,smooth]"):
        other_data = any(o.startswith("data=") for o in overrides or [])  # not the synthetic
        base = [
            *([] if other_data else TINY_DATA),
            f"cache_dir={cache_dir}",
            f"tracking.uri={mlflow_uri}",
            f"adjectives={adjectives}",
            "schedule=tiny",
            *(overrides or []),
        ]
        return compose_config(base)

    return _tiny


@pytest.fixture
def sigterm_raises(monkeypatch):
    """SIGTERM raises ``termination.Terminated`` for the test, as in a job."""
    import signal

    from tactile_exp.runtime import termination

    monkeypatch.setitem(termination._state, "received", 0)  # forgotten again after the test
    before = signal.signal(signal.SIGTERM, termination.handle)
    yield
    signal.signal(signal.SIGTERM, before)


def doc_block(page: str, first_line: str) -> str:
    """The fenced code block of ``docs/<page>`` whose first line starts with ``first_line``:
    an example a test runs as the page shows it."""
    import re

    text = (CONF.parent / "docs" / page).read_text()
    for body in re.findall(r"^```\w*\n(.*?)^```", text, re.S | re.M):
        if body.startswith(first_line):
            return body
    raise LookupError(f"docs/{page} has no code block starting with {first_line!r}")
