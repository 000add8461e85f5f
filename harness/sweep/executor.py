"""Where a sweep's jobs run: in this process, in a pool of spawned worker processes, or on
a Dask cluster. Every executor takes a top-level function and plain-dict jobs and yields
(job, result or exception) as jobs finish, so progress shows per job."""
from __future__ import annotations

import multiprocessing
import os
import socket
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterator

from estimator import InputError
from harness.cli.heap import keep_freed_memory

EXECUTORS = ("local", "dask")
BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def worker_threads(workers: int, cores: int | None = None) -> int:
    """Dr.Jit threads per worker so that ``workers`` processes share the cores without
    oversubscription."""
    return max(1, (cores or os.cpu_count() or 1) // max(workers, 1))


PARENT_POLL_S = 1.0   # how often a worker checks that the sweep that started it is alive


def _exit_with_parent(parent: int) -> None:
    """Worker thread: end this worker when its parent is gone (killed with SIGKILL, which no
    handler sees: the worker is then adopted by another process and would wait forever)."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _init_worker(parent: int, devices) -> None:
    """Pool initializer: watch the parent; with ``devices`` (a queue), take the next free
    CUDA device (before Dr.Jit starts); keep freed memory for reuse, as the command line does."""
    keep_freed_memory()
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()
    if devices is not None:
        os.environ["CUDA_VISIBLE_DEVICES"] = str(devices.get())


def run_jobs(fn: Callable[[dict], dict], jobs: list[dict], executor: str = "local", workers: int = 1,
             scheduler: str | None = None, gpus: int = 0) -> Iterator[tuple[dict, dict | BaseException]]:
    """Run ``fn`` on every job; yield (job, result) or (job, exception) in completion order.

    local, workers 1: in this process, in order. local, workers > 1: a process pool started
    with ``spawn`` (Dr.Jit state must never be forked); with ``gpus`` > 0 (the CUDA variant)
    the pool has one worker per GPU, at most ``workers``, each pinned to its own device
    through ``CUDA_VISIBLE_DEVICES``. dask: ``dask.distributed.Client``
    connected to ``scheduler`` (``tcp://HOST:PORT``) or to a scheduler object/address a
    caller made (e.g. a ``LocalCluster``); it needs ``pip install .[dask]``.
    """
    if executor not in EXECUTORS:
        raise InputError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if not jobs:
        return
    if executor == "dask":
        yield from _dask(fn, jobs, scheduler)
        return
    if workers <= 1:
        for job in jobs:
            try:
                yield job, fn(job)
            except (Exception, KeyboardInterrupt) as exc:  # noqa: BLE001 - reported per job
                if isinstance(exc, KeyboardInterrupt):
                    raise
                yield job, exc
        return
    context = multiprocessing.get_context("spawn")
    devices = None
    if gpus > 0:
        workers = min(workers, gpus)
        devices = context.Queue()
        for device in range(workers):
            devices.put(device)
    # spawned workers inherit the environment (they start on the first submit): one BLAS/OpenMP
    # pool each, of their share of the cores, and no progress bars of their own (the sweep's
    # one bar counts the jobs; the workers' bars overwrote each other)
    share = str(worker_threads(workers))
    worker_env = {**{k: share for k in BLAS_THREAD_VARIABLES}, "TQDM_DISABLE": "1"}
    saved = {k: os.environ.get(k) for k in worker_env}
    os.environ.update(worker_env)
    try:
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_init_worker,
                                   initargs=(os.getpid(), devices))
        try:
            futures = {pool.submit(fn, job): job for job in jobs}
            for future in as_completed(futures):
                exc = future.exception()
                yield futures[future], (exc if exc is not None else future.result())
        except BaseException:   # Ctrl-C, SIGTERM (the CLI's Terminated), a failing consumer: stop now
            workers_alive = list(getattr(pool, "_processes", {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for process in workers_alive:   # the running jobs too: their outputs are atomic
                process.terminate()
            raise
        pool.shutdown(wait=True)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


SCHEDULER_PROBE_S = 5.0   # a Dask scheduler sends its handshake at once; a listener that does not speak Dask, never


def probe_scheduler(address: str, timeout: float = SCHEDULER_PROBE_S) -> None:
    """Refuse an address that does not answer like a Dask scheduler: connect and wait up to
    ``timeout`` seconds for the first bytes of its handshake (``dask.distributed.Client`` waits
    forever on a port that accepts but stays silent, such as a bare listener or the dashboard)."""
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as conn:
            conn.settimeout(timeout)
            if not conn.recv(1):
                raise InputError(f"--scheduler {address}: the connection was closed without a Dask handshake")
    except socket.timeout:
        raise InputError(f"--scheduler {address}: no Dask handshake within {timeout:g} s (is it the dashboard's "
                         "port, or not a Dask scheduler?)") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot connect to the Dask scheduler {address!r}: {exc}") from None


def _dask(fn, jobs, scheduler):
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise InputError("--executor dask needs Dask: pip install '.[dask]'") from None
    if scheduler is None:
        raise InputError("--executor dask needs --scheduler tcp://HOST:PORT")
    if isinstance(scheduler, str) and scheduler.startswith("tcp://"):
        probe_scheduler(scheduler)
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, ValueError, TimeoutError) as exc:
        raise InputError(f"cannot connect to the Dask scheduler {scheduler!r}: {exc}") from None
    with client:
        futures = client.map(fn, jobs, pure=False)
        index = {f.key: job for f, job in zip(futures, jobs)}
        for future in dask_completed(futures):
            exc = future.exception()
            yield index[future.key], (exc if exc is not None else future.result())
