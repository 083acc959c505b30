"""Every shell command the documentation shows (README.md, docs/*.md) runs as written, and the
site builds strictly.

A command is a line of a ``bash``/``console`` block, or a ``$ `` line of a ``text`` block (a
console transcript); backslash-continued lines join, ``&&`` chains split. Each one is either

- run here (``-m slow``), from a scratch folder that stands for a clone (``.venv`` linked to this
  interpreter's, ``bench/`` to the repository's, ``.venv/bin`` first on ``PATH``: an activated
  venv), one MLflow store for all, pages in the nav's order (README first, so the main job's
  runs feed the report commands after it), with ``TACTILE_EXP_DOCS_TEST`` set
  (``tactile_exp/docs_test.py``: tiny schedule, small data, two adjectives). It must exit 0, or
  as its transcript says (``$ echo $?`` then the status; an ``error:`` line it shows must be
  printed); or
- in a block whose first line is ``# not run by the docs test: WHY`` (a long grid, a server, a
  file the reader brings): then a Hydra job (``python -m tactile_exp ...``) is composed here,
  every job of a ``-m`` grid, and a package module or bench script it names must exist; or
- a setup step (``python3.11 -m venv``, ``pip install``) or a command ``.ci/run`` itself runs
  (``pytest``, ``ruff``, ``mkdocs build --strict``): CI's own steps run those.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
MARKER = "# not run by the docs test:"
SHELL_LANGUAGES = ("bash", "console", "sh", "shell")
SETUP = ("python3.11 -m venv", "pip install", ".venv/bin/pip install")
ADJECTIVES = "metallic,soft"  # TACTILE_EXP_DOCS_TEST: Fig. 6's default and the walkthrough's
BLOCK = re.compile(r"^( *)```(\w*)[^\n]*\n(.*?)^\1```", re.S | re.M)
VENV_BIN = f"{Path(sys.executable).parent}"
# A line that only sets a variable for the lines after it (``ADJ='[a,b]'``, ``export X=...``).
ASSIGNMENT = re.compile(r"(export )?[A-Z_]+=('[^']*'|\"[^\"]*\"|\S+)")


@dataclass(frozen=True)
class Command:
    page: str
    line: int  # of the block's opening fence
    text: str  # as the reader would type it (continuations joined)
    marked: str | None  # why it is not run, when its block says so
    setup: tuple[str, ...] = ()  # the block's earlier variable assignments, run before it
    exit_status: int = 0  # what the page says it exits with
    error: str | None = None  # the error line the page shows it printing

    def __str__(self) -> str:
        return f"{self.page}:{self.line}: {self.text}"


def pages() -> list[Path]:
    """README.md, then the site's pages in the nav's order, then any page the nav leaves out."""
    nav = [ROOT / "docs" / p for p in nav_pages()]
    rest = sorted(set((ROOT / "docs").rglob("*.md")) - set(nav))
    return [ROOT / "README.md", *nav, *rest]


def nav_pages() -> list[str]:
    """The pages ``mkdocs.yml``'s nav lists, in order."""

    def walk(node) -> list[str]:
        if isinstance(node, str):
            return [node]
        if isinstance(node, list):
            return [p for item in node for p in walk(item)]
        return [p for value in node.values() for p in walk(value)]

    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    return walk(config["nav"])


def _joined(lines: list[str]) -> list[str]:
    out: list[str] = []
    for line in lines:
        if out and out[-1].endswith("\\"):
            out[-1] = out[-1][:-1].rstrip() + " " + line.strip()
        else:
            out.append(line)
    return out


def commands(page: Path) -> list[Command]:
    """The shell commands of one page, in order."""
    text = page.read_text()
    name = str(page.relative_to(ROOT))
    found: list[Command] = []
    for block in BLOCK.finditer(text):
        indent, language, body = len(block.group(1)), block.group(2), block.group(3)
        lines = [line[indent:] for line in body.splitlines()]
        transcript = language in ("console", "text") or any(line.startswith("$ ") for line in lines)
        if language not in SHELL_LANGUAGES and not (language == "text" and transcript):
            continue
        at = text[: block.start()].count("\n") + 1
        marked = lines[0][len(MARKER) :].strip() if lines and lines[0].startswith(MARKER) else None
        found += (
            _transcript(name, at, lines, marked) if transcript else _script(name, at, lines, marked)
        )
    return found


def _script(page: str, at: int, lines: list[str], marked: str | None) -> list[Command]:
    out, setup = [], []
    for line in _joined(lines):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if ASSIGNMENT.fullmatch(line):
            setup.append(line)
            continue
        out += [Command(page, at, part, marked, tuple(setup)) for part in _chain(line)]
    return out


def _transcript(page: str, at: int, lines: list[str], marked: str | None) -> list[Command]:
    """``$ `` lines are commands, the lines after one its output; ``$ echo $?`` and the line
    after it give the exit status of the command before."""
    entries: list[tuple[str, list[str]]] = []
    for line in lines:
        if line.startswith("$ "):
            entries.append((line[2:], []))
        elif entries and entries[-1][0].endswith("\\"):
            entries[-1] = (entries[-1][0][:-1].rstrip() + " " + line.strip(), entries[-1][1])
        elif entries:
            entries[-1][1].append(line)
    out, setup = [], []
    for i, (command, output) in enumerate(entries):
        if command.strip() == "echo $?":
            continue
        if ASSIGNMENT.fullmatch(command):
            setup.append(command)
            continue
        error = next((o for o in output if o.startswith("error:")), None)
        status = 2 if error else 0
        following = entries[i + 1] if i + 1 < len(entries) else None
        if following and following[0].strip() == "echo $?" and following[1]:
            status = int(following[1][0])
        out.append(Command(page, at, command, marked, tuple(setup), status, error))
    return out


def _chain(line: str) -> list[str]:
    return [part.strip() for part in line.split(" && ")]


def ci_steps() -> list[str]:
    """``.ci/run``'s command lines, without the venv prefix and environment assignments."""
    steps = []
    for line in _joined((ROOT / ".ci" / "run").read_text().splitlines()):
        line = re.sub(r"^(\w+=\S+ )+", "", line.strip())
        steps.append(_plain(line))
    return steps


def _plain(command: str) -> str:
    """Without a trailing comment, ``.venv/bin/`` prefixes and repeated blanks."""
    command = re.sub(r"\s+#.*$", "", command)
    return " ".join(command.replace(".venv/bin/", "").split())


def kind(command: Command, steps: list[str]) -> str:
    """run | marked | setup | ci."""
    if command.marked is not None:
        return "marked"
    if command.text.startswith(SETUP):
        return "setup"
    plain = _plain(command.text)
    if any(step == plain or step.startswith(plain + " ") for step in steps):
        return "ci"
    return "run"


def all_commands() -> list[Command]:
    return [c for page in pages() for c in commands(page)]


# ----------------------------------------------------------------- the site: strict and whole


def test_every_page_is_in_the_nav():
    """A page the nav leaves out is a warning, and strict mode (CI) aborts on warnings."""
    docs = ROOT / "docs"
    on_disk = {str(p.relative_to(docs)) for p in docs.rglob("*.md")}
    assert on_disk - set(nav_pages()) == set(), "add these pages to mkdocs.yml's nav"
    assert set(nav_pages()) - on_disk == set(), "the nav lists pages that do not exist"


def test_ci_builds_the_site_strictly_with_its_warnings_shown():
    builds = [s for s in ci_steps() if s.startswith("mkdocs build")]
    assert builds, ".ci/run does not build the documentation"
    for step in builds:
        words = step.split()
        assert "--strict" in words
        assert not {"-q", "--quiet"} & set(words), "--quiet hides the warnings strict mode counts"


def test_a_page_left_out_of_the_nav_fails_the_strict_build(tmp_path: Path):
    """What CI's build does with this repository's validation settings, on a two-page site."""
    mkdocs = shutil.which("mkdocs", path=VENV_BIN) or pytest.skip("mkdocs not installed")
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Home\n")
    (tmp_path / "docs" / "other.md").write_text("# Other\n")

    def build(nav: list) -> subprocess.CompletedProcess:
        site = {
            "site_name": "t",
            "docs_dir": "docs",
            "validation": config["validation"],
            "nav": nav,
        }
        (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(site))
        return subprocess.run(
            [mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        )

    assert build(["index.md", "other.md"]).returncode == 0
    left_out = build(["index.md"])
    assert left_out.returncode != 0
    assert "other.md" in left_out.stderr and 'not included in the "nav"' in left_out.stderr


# ----------------------------------------------------------------- the commands


def test_the_parser_reads_transcripts_scripts_and_markers(tmp_path: Path, monkeypatch):
    page = tmp_path / "page.md"
    page.write_text(
        "```bash\nA='[x]'\npython -m tactile_exp \\\n  adjectives=$A   # one\n"
        "python3.11 -m venv .venv && .venv/bin/python -m tactile_exp.report\n```\n\n"
        "```text\n$ python -m tactile_exp objective=mean_auc\nerror: objective: bad\n"
        "$ python -m tactile_exp -m x=1,2\nlog\n$ echo $?\n1\n```\n\n"
        f"```bash\n{MARKER} a long grid\npython -m tactile_exp -m sweep=table1\n```\n"
        "```python\nprint('not a shell block')\n```\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = commands(page)
    assert [c.text for c in found] == [
        "python -m tactile_exp adjectives=$A   # one",
        "python3.11 -m venv .venv",
        ".venv/bin/python -m tactile_exp.report",
        "python -m tactile_exp objective=mean_auc",
        "python -m tactile_exp -m x=1,2",
        "python -m tactile_exp -m sweep=table1",
    ]
    assert found[0].setup == ("A='[x]'",)
    assert (found[3].exit_status, found[3].error) == (2, "error: objective: bad")
    assert (found[4].exit_status, found[4].error) == (1, None)
    assert [c.marked for c in found] == [None] * 5 + ["a long grid"]
    assert [kind(c, ["python -m pytest"]) for c in found[:3]] == ["run", "setup", "run"]


def test_every_command_is_run_marked_or_a_ci_step():
    """The list the slow test runs is not empty, and every command falls in one class."""
    steps = ci_steps()
    kinds = {str(c): kind(c, steps) for c in all_commands()}
    assert "run" in kinds.values() and "marked" in kinds.values()
    placeholders = [c for c, k in kinds.items() if k == "run" and re.search(r"<[a-z ]+>", c)]
    assert placeholders == [], f"placeholders cannot run; mark their blocks: {placeholders}"


def _argv(command: Command) -> list[str]:
    """The arguments after ``python -m tactile_exp``, with the block's variables expanded."""
    script = "; ".join([*command.setup, f"printf '%s\\0' {_plain(command.text)}"])
    out = subprocess.run(["bash", "-c", script], capture_output=True, text=True, check=True)
    words = out.stdout.split("\0")[:-1]
    return words[words.index("tactile_exp") + 1 :]


COMPOSED: set[tuple[str, ...]] = set()


def _without_readers_config(argv: list[str]) -> list[str]:
    """``argv`` less ``--config-dir DIR`` (the reader's own folder, not here) and the options it
    alone gives (``model=my_rocket``: no such file in ``conf/``); the rest composes."""
    if "--config-dir" not in argv:
        return argv
    at = argv.index("--config-dir")
    rest = argv[:at] + argv[at + 2 :]
    conf = ROOT / "conf"

    def readers(arg: str) -> bool:
        group, _, option = arg.partition("=")
        return (
            bool(option)
            and (conf / group).is_dir()
            and not (conf / group / option).with_suffix(".yaml").is_file()
        )

    return [arg for arg in rest if not readers(arg)]


def _compose(argv: list[str]) -> int:
    """Compose every job of a Hydra command line as Hydra's basic sweeper expands it (the sweep
    group's own ``params`` too), or its one job without ``-m``; returns how many. Under another
    sweeper (a search picks values as it goes) the base config. Launcher settings are left to
    Hydra: their plugins are extras."""
    from hydra import compose, initialize_config_dir
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    overrides = [a for a in argv if a not in ("-m", "--multirun", "...")]  # ...: "and so on"
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        parser = OverridesParser.create(GlobalHydra.instance().config_loader())
        fixed = [
            o.input_line for o in parser.parse_overrides(overrides) if not o.is_sweep_override()
        ]
        ours = [o for o in fixed if not o.lstrip("+~").startswith("hydra")]
        if "-m" not in argv and "--multirun" not in argv:
            compose("config", ours)
            return 1
        base = compose("config", fixed, return_hydra_config=True)
        sweeper = base.hydra.sweeper
        if sweeper.get("_target_") != f"{BasicSweeper.__module__}.{BasicSweeper.__name__}":
            compose("config", ours)
            return 1
        params = [f"{k}={v}" for k, v in (sweeper.get("params") or {}).items()]
        parsed = parser.parse_overrides([*params, *overrides])
        jobs = [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]
        for job in jobs:
            key = tuple(o for o in job if not o.lstrip("+~").startswith("hydra"))
            if key not in COMPOSED:  # many commands share jobs (sweep=table1)
                compose("config", list(key))
                COMPOSED.add(key)
    return len(jobs)


MARKED = [c for c in all_commands() if kind(c, ci_steps()) == "marked"]


@pytest.mark.slow
@pytest.mark.parametrize("command", MARKED, ids=str)
def test_a_marked_command_composes(command: Command):
    """Not run, but its jobs compose and what it names exists."""
    plain = _plain(command.text)
    if plain.startswith("python -m tactile_exp "):
        assert _compose(_without_readers_config(_argv(command))) >= 1
    elif m := re.match(r"python -m (tactile_exp(\.\w+)+)", plain):
        path = ROOT / m.group(1).replace(".", "/")
        assert path.with_suffix(".py").exists() or (path / "__main__.py").exists(), plain
    elif m := re.match(r"python (bench/\S+\.py)", re.sub(r"^PYTHONPATH=\S+ ", "", plain)):
        assert (ROOT / m.group(1)).exists(), plain


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory, cache_dir: Path) -> tuple[Path, dict]:
    """A scratch folder standing for a clone with its venv, and the environment to run in."""
    folder = tmp_path_factory.mktemp("clone")
    (folder / ".venv").symlink_to(Path(sys.executable).parent.parent)
    (folder / "bench").symlink_to(ROOT / "bench")
    env = {
        **os.environ,
        "PATH": f"{VENV_BIN}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": str(ROOT),
        "TACTILE_EXP_DOCS_TEST": ADJECTIVES,
        "TACTILE_EXP_CACHE": str(cache_dir),
        "MLFLOW_TRACKING_URI": f"sqlite:///{folder}/mlflow.db",
        "HYDRA_FULL_ERROR": "0",
    }
    return folder, env


RUN = [c for c in all_commands() if kind(c, ci_steps()) == "run"]


@pytest.mark.slow
@pytest.mark.parametrize("command", RUN, ids=str)
def test_a_command_runs_as_the_page_says(command: Command, clone):
    folder, env = clone
    script = "\n".join([*command.setup, command.text])
    done = subprocess.run(
        ["bash", "-c", script], cwd=folder, env=env, capture_output=True, text=True, timeout=300
    )
    said = f"{command}\nexit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    assert done.returncode == command.exit_status, said
    if command.error:
        assert command.error.rstrip(" .") in done.stderr + done.stdout, said
