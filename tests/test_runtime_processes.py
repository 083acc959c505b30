"""Processes as /proc shows them, and the one way to stop child processes
(``tactile_exp.runtime.processes``)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from tactile_exp.runtime import processes

# A child that says when it is ready; ``stubborn`` ignores SIGTERM, the other ends on it.
READY = "import signal, time; {}print(flush=True); time.sleep(60)"
STUBBORN = "signal.signal(signal.SIGTERM, signal.SIG_IGN); "


def _child(code: str) -> subprocess.Popen:
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    child.stdout.readline()  # type: ignore[union-attr]
    return child


def test_alive_only_probes_and_trusts_what_it_cannot_check(monkeypatch):
    child = subprocess.Popen(["sleep", "30"])
    try:
        start = processes.process_start(child.pid)
        assert processes.process_alive(child.pid, start) and processes.process_alive(child.pid)
        assert not processes.process_alive(child.pid, str(int(start) + 1))  # a reused pid
        assert child.poll() is None  # probing sent no signal that ends it
        monkeypatch.setattr(processes, "stat_fields", lambda pid: [])
        assert processes.process_alive(child.pid, "123")  # /proc unreadable: assume alive
    finally:
        child.kill()
        child.wait()

    def not_ours(pid, signal):
        raise PermissionError(pid)

    monkeypatch.setattr(processes.os, "kill", not_ours)
    assert processes.process_alive(child.pid)  # another user's live process


def test_process_start_survives_parentheses_in_the_process_name(tmp_path):
    odd = tmp_path / "a) b c"  # /proc/<pid>/stat: "<pid> (a) b c) S ...": split at the last ")"
    odd.symlink_to("/bin/sleep")
    child = subprocess.Popen([str(odd), "30"])
    try:
        stat = Path(f"/proc/{child.pid}/stat").read_text()
        assert "(a) b c)" in stat
        start = processes.process_start(child.pid)
        assert start == stat[stat.rindex(")") + 1 :].split()[19] and start.isdigit()
    finally:
        child.kill()
        child.wait()
    assert processes.process_start(child.pid) == ""  # gone: unknown


def test_process_tags_name_this_process():
    tags = processes.process_tags()
    assert tags["pid"] == str(os.getpid())
    assert tags["pid_start"] == processes.process_start(os.getpid()) != ""
    assert processes.process_alive(int(tags["pid"]), tags["pid_start"])


def test_children_and_resource_trackers_are_told_apart():
    tracker_like = "from multiprocessing.resource_tracker import main; " + READY.format("")
    kids = [_child(READY.format("")), _child(tracker_like)]
    try:
        found = processes.children(os.getpid())
        assert {k.pid for k in kids} <= set(found)
        assert [processes.is_resource_tracker(k.pid) for k in kids] == [False, True]
        assert processes.children(kids[0].pid) == []
    finally:
        for k in kids:
            k.kill()
            k.wait()
    assert not processes.is_resource_tracker(kids[1].pid)  # gone: nothing to read


def test_stop_terminates_then_kills_what_ignores_sigterm_and_never_reaps():
    polite, stubborn = _child(READY.format("")), _child(READY.format(STUBBORN))
    try:
        start = time.monotonic()
        killed = processes.stop([polite.pid, stubborn.pid], grace_s=1.0)
        took = time.monotonic() - start
        assert killed == [stubborn.pid]  # only the one past the grace period
        assert 1.0 <= took < 1.0 + processes.KILLED_WAIT_S
        assert not processes.process_alive(polite.pid) and not processes.process_alive(stubborn.pid)
        # Ended, but left for their parent to reap (here: this test, as Popen's owner).
        assert processes.stat_fields(polite.pid)[0] == "Z"
        assert polite.wait(timeout=5) == -15 and stubborn.wait(timeout=5) == -9
    finally:
        for p in (polite, stubborn):
            p.kill()
            p.wait()


def test_stop_returns_as_soon_as_every_process_ended():
    polite = [_child(READY.format("")) for _ in range(2)]
    try:
        start = time.monotonic()
        assert processes.stop([p.pid for p in polite], grace_s=30.0) == []
        assert time.monotonic() - start < 10.0  # not the grace period
        assert [p.wait(timeout=5) for p in polite] == [-15, -15]
        assert processes.stop([p.pid for p in polite], grace_s=30.0) == []  # already gone
    finally:
        for p in polite:
            p.kill()
            p.wait()


def test_stop_leaves_a_reused_pid_alone(monkeypatch):
    """A PID whose process ended and was reaped may be reused: the later process has another
    start time, and is neither waited for nor signalled."""
    child = subprocess.Popen(["sleep", "30"])
    try:
        real = processes.process_start
        monkeypatch.setattr(processes, "process_start", lambda pid: str(int(real(pid)) - 1))
        start = time.monotonic()
        assert processes.stop([child.pid], grace_s=30.0) == []
        assert time.monotonic() - start < 5.0
        assert child.poll() is None  # no signal reached it
    finally:
        child.kill()
        child.wait()
