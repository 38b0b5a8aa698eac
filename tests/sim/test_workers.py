"""`sim.workers.run_tasks`: every result once, the first error as one line, never a hang.

The tasks are stdlib functions (they pickle by name into a spawned worker): `math.sqrt` fails
on -1, `os._exit` ends its worker, `time.sleep` keeps one busy, and `os.system` runs a shell
that can `kill -9` the worker it runs in (its parent, ``$PPID``).
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import signal
import time

import pytest

from edge.errors import ConfigError, DataError
from sim import workers

CTX = mp.get_context("spawn")


def _no_children_left() -> None:
    assert not mp.active_children(), "run_tasks left worker processes behind"


def test_every_result_comes_back_once():
    got = sorted(workers.run_tasks(CTX, 2, math.sqrt, [float(i * i) for i in range(20)]))
    assert got == [float(i) for i in range(20)]
    _no_children_left()


def test_no_tasks_start_no_workers():
    assert list(workers.run_tasks(CTX, 2, math.sqrt, [])) == []
    _no_children_left()


def test_a_failing_task_ends_the_run_with_one_line():
    with pytest.raises(DataError, match=r"^a worker failed \(ValueError: math domain error\)$"):
        list(workers.run_tasks(CTX, 2, math.sqrt, [4.0, -1.0, 9.0, 16.0]))
    _no_children_left()


def test_a_failing_initializer_fails_the_run_instead_of_respawning():
    t0 = time.monotonic()
    with pytest.raises(DataError, match="ValueError"):
        list(workers.run_tasks(CTX, 2, math.sqrt, [1.0, 4.0], initializer=math.sqrt, initargs=(-1.0,)))
    assert time.monotonic() - t0 < 60
    _no_children_left()


def test_a_worker_that_dies_ends_the_run_instead_of_waiting_forever():
    t0 = time.monotonic()
    with pytest.raises(DataError, match="exited with code 3; run the same command again to resume"):
        list(workers.run_tasks(CTX, 2, os._exit, [3]))
    assert time.monotonic() - t0 < 60
    _no_children_left()


def _kill_my_worker(marker=None) -> str:
    """A shell command that SIGKILLs the worker running it (once, if ``marker`` is given)."""
    if marker is None:
        return "kill -9 $PPID; sleep 5"
    return f"test -e {marker} || {{ touch {marker}; kill -9 $PPID; sleep 5; }}"


def test_the_task_of_a_killed_worker_goes_to_another_worker(tmp_path):
    told = []
    tasks = ["true", _kill_my_worker(tmp_path / "killed-once"), "true", "true", "true"]
    got = list(workers.run_tasks(CTX, 2, os.system, tasks, on_retry=told.append))
    assert got == [0] * len(tasks)  # every task once, the killed one run again by the other worker
    assert (tmp_path / "killed-once").exists()
    assert told == ["a worker process was killed (SIGKILL: the out-of-memory killer does this); "
                    "its task goes to the 1 remaining worker"]
    _no_children_left()


def test_the_last_worker_killed_ends_the_run_with_one_line():
    t0 = time.monotonic()
    told = []
    with pytest.raises(DataError, match=r"killed \(SIGKILL.*run the same command again to resume"):
        list(workers.run_tasks(CTX, 2, os.system, [_kill_my_worker(), _kill_my_worker()], on_retry=told.append))
    assert len(told) == 1  # the first death handed its task on; the second left nobody
    assert time.monotonic() - t0 < 60
    _no_children_left()


def test_closing_the_iterator_stops_busy_workers():
    it = workers.run_tasks(CTX, 2, time.sleep, [0.0, 600.0, 600.0])
    assert next(it) is None
    t0 = time.monotonic()
    it.close()
    assert time.monotonic() - t0 < 30
    _no_children_left()


def test_death_messages_name_the_cause_and_the_fix():
    assert "SIGKILL: the out-of-memory killer" in str(workers._death(-signal.SIGKILL))
    assert "killed by signal SIGSEGV" in str(workers._death(-signal.SIGSEGV))
    assert "fewer --workers" in str(workers._death(1))


def test_errors_cross_the_process_boundary_as_their_own_class():
    exc = workers._portable(ConfigError("bad value"))
    assert type(exc) is ConfigError and str(exc) == "bad value"
    exc = workers._portable(RuntimeError("first line\nsecond line"))
    assert type(exc) is DataError and str(exc) == "a worker failed (RuntimeError: first line)"


def test_a_retried_shard_counts_its_frames_once():
    """The progress bar's rule: a shard made again after a kill never counts past its size."""
    from sim.dataset import count_frame_once

    counted: dict[int, int] = {}
    first = [count_frame_once(counted, (20, 30)) for _ in range(4)]  # killed after 4 frames
    again = [count_frame_once(counted, (20, 30)) for _ in range(10)]  # made again, all 10
    other = [count_frame_once(counted, (30, 35)) for _ in range(5)]
    assert first == [True] * 4
    assert again == [True] * 6 + [False] * 4
    assert sum(first + again) == 10 and all(other)
