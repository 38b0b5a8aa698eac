"""A process pool for ``depthseg-sim``'s shards that fails fast and never hangs.

Why not `multiprocessing.Pool`: it replaces a worker whose initializer raises, forever; it waits
forever for the task of a worker that was killed (the out-of-memory killer, ``kill -9``:
CPython issue 66587), so a run that lost one worker never ended; and its ``terminate()`` can
deadlock on its own queue locks (CPython issue 78178), which once hung a test of a failing
worker for minutes. Here every worker pulls ``(index, task)`` from one queue and puts
``(index, ok, value)`` on another; the parent waits for results with a timeout, checks between
waits that its workers are alive, and on any way out (done, an error, Ctrl-C) terminates and then
kills them itself. A shard is a pure function of its frame range and appears under its final name
only when complete, so a run stopped this way loses only the shards in flight: the same command
resumes it.
"""

from __future__ import annotations

import queue
import signal
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from edge.errors import DataError, DepthsegError, first_line

__all__ = ["run_tasks", "POLL_S"]

POLL_S = 0.5  # how often the parent looks at its workers while no result arrives
STOP_S = 5.0  # how long a worker gets to end after SIGTERM before SIGKILL


def _portable(exc: BaseException) -> DepthsegError:
    """An exception that survives pickling and prints as one line in the parent."""
    if isinstance(exc, DepthsegError):
        return type(exc)(str(exc))
    return DataError(f"a worker failed ({type(exc).__name__}: {first_line(exc)})")


def _serve(tasks, results, initializer: Callable[..., None] | None, initargs: tuple, func: Callable[[Any], Any]) -> None:
    """A worker's loop: set up once, then run tasks until the sentinel; stop at the first error."""
    import multiprocessing as mp

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops us
    parent = mp.parent_process()
    try:
        if initializer is not None:
            initializer(*initargs)
    except BaseException as exc:  # noqa: BLE001 - reported by the parent as one line
        results.put((None, False, _portable(exc)))
        return
    for index, task in iter(tasks.get, None):
        if parent is not None and not parent.is_alive():
            return  # the run is gone: do not keep writing shards for nobody
        try:
            value = func(task)
        except BaseException as exc:  # noqa: BLE001 - reported by the parent as one line
            results.put((index, False, _portable(exc)))
            return
        results.put((index, True, value))


def _death(exitcode: int) -> DataError:
    if exitcode == -signal.SIGKILL:
        how = "was killed (SIGKILL: the out-of-memory killer does this)"
    elif exitcode < 0:
        how = f"was killed by signal {signal.Signals(-exitcode).name}"
    else:
        how = f"exited with code {exitcode}"
    return DataError(f"a worker process {how}; run the same command again to resume "
                     "(complete shards are kept), with fewer --workers if memory is short")


def _stop(procs: Sequence[Any]) -> None:
    for p in procs:
        if p.exitcode is None:
            p.terminate()
    for p in procs:
        p.join(STOP_S)
        if p.exitcode is None:
            p.kill()
            p.join(STOP_S)


def run_tasks(
    ctx: Any,
    workers: int,
    func: Callable[[Any], Any],
    tasks: Sequence[Any],
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
) -> Iterator[Any]:
    """Run ``func`` on every task in ``workers`` processes; yield the results as they complete.

    ``ctx``: a multiprocessing context (``spawn`` for the simulator: no fork after open3d's
    threads exist). ``func``, ``initializer`` and the tasks must pickle. The first error of a
    task or of an initializer, or a worker that dies, ends the run with a `DepthsegError` (one
    line); the workers are always stopped when the iterator ends, is closed, or raises.
    """
    tasks = list(tasks)
    if not tasks:
        return
    n = max(1, min(int(workers), len(tasks)))
    todo, results = ctx.Queue(), ctx.Queue()
    todo.cancel_join_thread()  # unread tasks must not keep the parent alive at exit
    for item in enumerate(tasks):
        todo.put(item)
    for _ in range(n):
        todo.put(None)
    procs = [ctx.Process(target=_serve, args=(todo, results, initializer, initargs, func), daemon=True)
             for _ in range(n)]
    try:
        for p in procs:
            p.start()
        pending = len(tasks)
        while pending:
            try:
                _, ok, value = results.get(timeout=POLL_S)
            except queue.Empty:
                codes = [p.exitcode for p in procs]
                if any(c is None for c in codes) and not any(codes):
                    continue  # working (a worker that ended cleanly put its error first)
                try:  # one died, or all ended: what they flushed before ending comes first
                    _, ok, value = results.get(timeout=POLL_S)
                except queue.Empty:
                    bad = [c for c in codes if c]
                    raise (_death(bad[0]) if bad else DataError(
                        f"the workers ended with {pending} tasks not done; run the same command again to resume")) from None
            if not ok:
                raise value
            pending -= 1
            yield value
    finally:
        _stop(procs)
        todo.close()
        results.close()
