"""A process pool for ``depthseg-sim``'s shards that fails fast, never hangs and survives a kill.

Why not `multiprocessing.Pool`: it replaces a worker whose initializer raises, forever; it waits
forever for the task of a worker that was killed (the out-of-memory killer, ``kill -9``:
CPython issue 66587), so a run that lost one worker never ended; and its ``terminate()`` can
deadlock on its own queue locks (CPython issue 78178), which once hung a test of a failing
worker for minutes. Here each worker has its own pipe and nothing else is shared, so a worker
killed at any moment cannot leave a lock held that the others wait for. The parent hands each
worker one task at a time and so always knows which task a worker holds: a task whose worker
was killed by a signal is handed to a live worker (as Ray retries a task whose worker died),
and the run stops with one line only when no worker is left, when a task raises, or when a
worker exits by itself. On any way out (done, an error, Ctrl-C) the parent terminates and then
kills its workers itself. A shard is a pure function of its frame range and appears under its
final name only when complete, so a stopped run loses only the shards in flight: the same
command resumes it.
"""

from __future__ import annotations

import signal
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import wait
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


def _serve(conn, initializer: Callable[..., None] | None, initargs: tuple, func: Callable[[Any], Any]) -> None:
    """A worker's loop: set up once, then run the tasks the parent sends until ``None``.

    Replies ``(index, ok, value)``; stops after the first error. A closed pipe means the parent is
    gone: then there is nobody to write shards for.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops us
    try:
        if initializer is not None:
            initializer(*initargs)
    except BaseException as exc:  # noqa: BLE001 - reported by the parent as one line
        conn.send((None, False, _portable(exc)))
        return
    while True:
        try:
            item = conn.recv()
        except (EOFError, OSError):
            return
        if item is None:
            return
        index, task = item
        try:
            value = func(task)
        except BaseException as exc:  # noqa: BLE001 - reported by the parent as one line
            conn.send((index, False, _portable(exc)))
            return
        conn.send((index, True, value))


def _how(exitcode: int) -> str:
    if exitcode == -signal.SIGKILL:
        return "was killed (SIGKILL: the out-of-memory killer does this)"
    if exitcode < 0:
        return f"was killed by signal {signal.Signals(-exitcode).name}"
    return f"exited with code {exitcode}"


def _death(exitcode: int) -> DataError:
    return DataError(f"a worker process {_how(exitcode)}; run the same command again to resume "
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


class _Worker:
    """One process, the parent's end of its pipe, and the index of the task it holds (or None)."""

    def __init__(self, ctx: Any, initializer, initargs: tuple, func) -> None:
        self.conn, self.child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(self.child, initializer, initargs, func), daemon=True)
        self.held: int | None = None


def run_tasks(
    ctx: Any,
    workers: int,
    func: Callable[[Any], Any],
    tasks: Sequence[Any],
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
    on_retry: Callable[[str], None] | None = None,
) -> Iterator[Any]:
    """Run ``func`` on every task in ``workers`` processes; yield the results as they complete.

    Args:
        ctx: a multiprocessing context (``spawn`` for the simulator: no fork after open3d's
            threads exist).
        workers: how many processes (at most one a task).
        func: run on each task in a worker; it, ``initializer`` and the tasks must pickle.
        tasks: the tasks; each result is yielded once, in completion order.
        initializer, initargs: run once in each worker before its first task.
        on_retry: told (one line) when the task of a worker killed by a signal goes to another.

    A task or an initializer that raises, a worker that exits by itself while it holds a task, or
    the last worker killed ends the run with a `DepthsegError` (one line); the workers are always
    stopped when the iterator ends, is closed, or raises.
    """
    tasks = list(tasks)
    if not tasks:
        return
    todo = deque(range(len(tasks)))
    pool = [_Worker(ctx, initializer, initargs, func) for _ in range(max(1, min(int(workers), len(tasks))))]
    procs = [w.proc for w in pool]

    def feed(w: _Worker) -> None:
        """Hand ``w`` the next task; without one it waits idle (a killed worker's task may come)."""
        w.held = todo.popleft() if todo else None
        if w.held is not None:
            try:
                w.conn.send((w.held, tasks[w.held]))
            except OSError:
                pass  # it just died: its end of file comes next, and the task it holds goes on

    try:
        for w in pool:
            w.proc.start()
            w.child.close()  # only the worker holds its end now: its death reads as end of file
            feed(w)
        pending = len(tasks)
        while pending:
            for conn in wait([w.conn for w in pool], timeout=POLL_S):
                w = next(v for v in pool if v.conn is conn)
                try:
                    msg = conn.recv()
                except (EOFError, OSError):  # the worker is gone
                    msg = None
                if msg is None:
                    w.proc.join(STOP_S)
                    code = w.proc.exitcode if w.proc.exitcode is not None else -signal.SIGKILL
                    pool.remove(w)
                    conn.close()
                    if w.held is None and pool:
                        continue
                    if code >= 0 or not pool:
                        raise _death(code)
                    todo.appendleft(w.held)
                    if on_retry is not None:
                        n = len(pool)
                        on_retry(f"a worker process {_how(code)}; its task goes to the {n} remaining worker{'s' * (n > 1)}")
                    for v in pool:
                        if v.held is None:
                            feed(v)
                    continue
                _, ok, value = msg
                if not ok:
                    raise value
                pending -= 1
                yield value
                feed(w)
        for w in pool:  # all done: idle workers end by themselves
            try:
                w.conn.send(None)
            except OSError:
                pass
        for p in procs:
            p.join(STOP_S)
    finally:
        _stop(procs)
        for w in pool:
            w.conn.close()
