"""Run the shards of ``depthseg-sim`` as Ray tasks (``--ray [ADDRESS]``), one shard a task.

Why it needs nothing new for correctness: a shard is a pure function of (seed, config, its
frame range) and appears under its final name only when complete (`edge.io.FrameWriter`),
so where and in which order the tasks run does not matter, and a task that dies (worker killed,
node lost) leaves at most a temporary file. Ray retries a task whose worker died
(``max_retries``); when the retries are exhausted the run stops with one line, and running the
same command again regenerates exactly the missing shards.

On a cluster the output folder must be one shared file system (NFS, Lustre, a bucket mounted
with a POSIX layer) seen under the same path by every node, and depthseg with its ``sim``
extra must be installed on every node (or shipped with ``RAY_RUNTIME_ENV``/a Ray runtime
environment). The driver needs no CPU of its own: it only submits tasks and writes the manifest.

Ray is an optional extra (``pip install 'depthseg[ray]'``); it is imported only here.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from edge.errors import ConfigError, DataError, first_line

__all__ = ["import_ray", "check_address", "check_nodes", "run_shards"]

MAX_RETRIES = 3  # Ray re-runs a task whose worker died this many times before the run stops

RAY_MISSING = "`ray` needs Ray, an optional extra: pip install 'depthseg[ray]' (or: pip install 'ray[default]')"


def import_ray():
    """The ``ray`` module, or a ConfigError naming the extra to install."""
    try:
        import ray
    except ImportError:
        raise ConfigError(RAY_MISSING) from None
    return ray


def _refusal(engines: dict[str, str] | None) -> str | None:
    """The one-line refusal of a node whose physics or ray-casting versions differ from the
    driver's ``engines`` (`sim.dataset.engine_mismatch`), or None when they agree."""
    import socket

    from sim import dataset

    bad = dataset.engine_mismatch(engines)
    if bad is None:
        return None
    name, want, have = bad
    return (
        f"the Ray worker on {socket.gethostname()} has {name} {have} where the driver has {want}, "
        f"so its frames would differ; run pip install '{name}=={want}' on every node (tools/constraints.txt)"
    )


def _shard_task(task: tuple[int, int], config_dict: dict, seed: int, library_paths: list[str] | None, out: str,
                engines: dict[str, str] | None = None) -> dict:
    """Body of one Ray task: the same worker code as ``--workers`` (set up once per Ray worker).

    ``engines``: the driver's `sim.dataset.engines`. A node with other physics or ray-casting
    versions would write other frames under the same seed, so its task fails before writing
    (`check_nodes` refuses such a node up front; this catches one that joined later).
    """
    from sim import dataset

    refusal = _refusal(engines)
    if refusal is not None:
        raise DataError(refusal)

    key = (repr(config_dict), seed, tuple(library_paths or ()), out)
    if dataset._W.get("ray_key") != key:
        dataset._init_worker(config_dict, seed, library_paths, out, None, pooled=False)
        dataset._W["ray_key"] = key
    return dataset._write_shard(task)


PROBE_TIMEOUT_S = 120.0  # a node that cannot start one worker in this time is reported, not waited on


def check_nodes(ray, engines: dict[str, str], timeout_s: float = PROBE_TIMEOUT_S) -> None:
    """Refuse the run, before any shard is submitted, when a live node has other versions.

    One zero-CPU task pinned to each live node compares its versions with the driver's, so a
    mixed cluster stops with one line and no work is started (and none cancelled).

    Args:
        ray: the connected ``ray`` module.
        engines: the driver's `sim.dataset.engines`.
        timeout_s: how long to wait for every node's answer.
    """
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    probe = ray.remote(num_cpus=0, max_retries=0)(_refusal)  # the per-task rule, run once a node
    refs = [
        probe.options(scheduling_strategy=NodeAffinitySchedulingStrategy(node_id=n["NodeID"], soft=False)).remote(engines)
        for n in ray.nodes()
        if n.get("Alive")
    ]
    try:
        answers = ray.get(refs, timeout=timeout_s)
    except ray.exceptions.GetTimeoutError:
        raise DataError(
            f"a Ray node did not answer the version check in {timeout_s:.0f} s; check that every node can start "
            "a worker ('ray status') and run again"
        ) from None
    except ray.exceptions.RayError as exc:
        raise DataError(f"the Ray version check failed ({type(exc).__name__}: {first_line(exc)}); run again") from None
    for refusal in answers:
        if refusal is not None:
            raise DataError(f"{refusal}; nothing was written")


CONNECT_TIMEOUT_S = 5.0


def check_address(address: str) -> None:
    """Refuse a ``host:port`` nobody answers on, before Ray retries it for ten minutes.

    ``auto`` (and any address without a port) is left to Ray, which finds a local cluster
    through its session files and fails fast when there is none.
    """
    import socket

    hostport = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = hostport.rpartition(":")
    if not sep:
        return
    if not host:
        raise ConfigError(f"`ray` {address}: no host name before the port; give HOST:PORT or 'auto'")
    try:
        port_no = int(port)
    except ValueError:
        raise ConfigError(f"`ray` {address}: the port '{port[:20]}' is not a number; give HOST:PORT or 'auto'") from None
    if not 0 < port_no < 65536:
        raise ConfigError(f"`ray` {address}: port {port_no} is outside 1-65535; give HOST:PORT or 'auto'")
    try:
        socket.create_connection((host.strip("[]"), port_no), timeout=CONNECT_TIMEOUT_S).close()
    except (OSError, UnicodeError) as exc:
        reason = exc.strerror or type(exc).__name__ if isinstance(exc, OSError) else "bad host name"
        raise ConfigError(
            f"`ray` {address}: no Ray cluster answers there ({reason}); start one with 'ray start --head' or "
            "check the address"
        ) from None


def _connect(ray, address: str | None, workers: int) -> bool:
    """Connect to ``address`` or start a local Ray with ``workers`` CPUs; True if we started it."""
    if ray.is_initialized():
        return False
    if address:
        check_address(address)
        try:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise ConfigError(f"`ray` {address}: cannot connect to a Ray cluster ({exc}); start one with 'ray start --head'") from None
        return True
    # Local: make this checkout importable by the workers whatever the current folder is.
    root = str(Path(__file__).resolve().parents[1])
    pp = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
    ray.init(
        num_cpus=int(workers),
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
        object_store_memory=100 * 1024 * 1024,  # tasks return small dicts; shards go to disk
        runtime_env={"env_vars": {"PYTHONPATH": pp}},
    )
    return True


def run_shards(
    todo: Iterable[tuple[int, int]],
    config_dict: dict,
    seed: int,
    library_paths: list[str] | None,
    out: str | Path,
    record: Callable[[dict[str, Any]], None],
    address: str | None = None,
    workers: int = 1,
    max_retries: int | None = None,
) -> None:
    """Run one task per shard; ``record`` is called in the driver as each shard completes.

    Raises DataError (after cancelling what is still running) when a task fails for good.
    """
    ray = import_ray()
    started = _connect(ray, address, workers)
    try:
        task = ray.remote(num_cpus=1, max_retries=int(MAX_RETRIES if max_retries is None else max_retries))(_shard_task)
        cfg_ref = ray.put(config_dict)
        from sim.dataset import engines

        mine = engines()
        check_nodes(ray, mine)
        pending = [task.remote(t, cfg_ref, int(seed), library_paths, str(out), mine) for t in todo]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            try:
                record(ray.get(done[0]))
            except ray.exceptions.RayError as exc:
                for ref in pending:  # a plain request: the run stops anyway (force=True would kill worker processes)
                    ray.cancel(ref)
                cause = getattr(exc, "cause", None)
                if isinstance(cause, DataError):  # a task's own one-line refusal (another node's versions)
                    raise DataError(f"{cause}; complete shards are kept") from None
                raise DataError(
                    f"a Ray task failed ({type(exc).__name__}: {first_line(exc)}); complete shards are kept: "
                    "run the same command again to finish"
                ) from None
    finally:
        if started:
            ray.shutdown()
