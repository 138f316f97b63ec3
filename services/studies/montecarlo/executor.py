"""Runs a Monte-Carlo in chunks on a Dask cluster, in-process on this machine unless given a scheduler.

The study's runs are split into chunks of CHUNK_RUNS (`plan_chunks`); a task — a top-level function of an
importable module, `task(chunk) -> result`, picklable — simulates one chunk; `run_chunks` maps it over
the chunks on a `dask.distributed` cluster and returns the results in chunk order. Without a scheduler it
starts a LocalCluster of single-threaded worker processes on 127.0.0.1 (TLS with throwaway certificates, no
dashboard) and closes it at the end, also on an error or Ctrl-C; with one (`tcp://HOST:PORT`, or
`tls://HOST:PORT` with the certificates in Dask's configuration, `distributed.comm.tls.*`) it connects to it.

Reproducible by construction: the split depends on (runs, seed) only, never on the number of workers,
and a task draws its randomness from `chunk_rng(chunk)` only — `SeedSequence(seed, spawn_key=(index,))`,
the index-th child of `SeedSequence(seed).spawn(…)`, independent streams. A chunk's result is therefore a
function of (seed, chunk index, chunk runs): the same on 1 worker, 2 workers or a remote cluster, in
whatever order the chunks finish. (Changing CHUNK_RUNS changes the split, hence the draws.)

How `sharedctl faults montecarlo` uses it (command.py owns the progress bar, work.py the task):

    chunks = plan_chunks(args.runs, args.seed, args.chunk_runs)
    results, info = run_chunks(partial(run_chunk, duration=…, families=…), chunks, workers=args.workers,
                               scheduler=scheduler, on_result=…)     # on_result advances the progress bar
    summary = summarize(results, wall)          # upper_95 per family; info.workers into the JSON

Needs the `montecarlo` extra (dask[distributed]); without it `run_chunks` raises a ModuleNotFoundError
that says so.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

# Runs per chunk: a chunk is one Dask task, one batch of the fault loop. The batch's cost per control period
# is a fixed part (numpy calls) plus a part per robot, so larger batches run more robots per second: on this
# 2-core machine a chunk of 1024 runs about 2.5 times as many runs a second as one of 256, and 4096 another
# 1.3 times; 1024 still leaves ~100 chunks for 100 000 runs to keep every worker busy to the end and the
# progress bar moving. Part of the split, hence of the results.
CHUNK_RUNS = 1024

# numpy's BLAS/OpenMP pools in each worker process: one thread, so N workers on N cores do not oversubscribe.
SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

CONNECT_TIMEOUT_S = 10      # reaching a --scheduler
WORKERS_TIMEOUT_S = 60      # a --scheduler with no worker yet: wait this long for one

OnResult = Callable[["Chunk", object, int, int], None]


@dataclass(frozen=True)
class Chunk:
    """Runs first_run … first_run + runs − 1 of the study seeded with `seed`; the index-th chunk."""

    index: int
    first_run: int
    runs: int
    seed: int


@dataclass(frozen=True)
class RunInfo:
    """How a `run_chunks` call ran: the workers the cluster had when the chunks were submitted, the seconds
    spent starting (or reaching) the cluster, and the wall time of the whole call, start-up included."""

    workers: int
    startup_seconds: float
    wall_seconds: float


def plan_chunks(runs: int, seed: int, chunk_runs: int = CHUNK_RUNS) -> list[Chunk]:
    """The study's runs in chunks of `chunk_runs` (the last one shorter), in order; every chunk carries `seed`."""
    if runs < 1:
        raise ValueError(f"plan_chunks: runs must be at least 1, got {runs}")
    if chunk_runs < 1:
        raise ValueError(f"plan_chunks: chunk_runs must be at least 1, got {chunk_runs}")
    if seed < 0:
        raise ValueError(f"plan_chunks: seed must be a non-negative integer (numpy SeedSequence), got {seed}")
    return [Chunk(index=i, first_run=first, runs=min(chunk_runs, runs - first), seed=seed)
            for i, first in enumerate(range(0, runs, chunk_runs))]


def chunk_rng(chunk: Chunk) -> np.random.Generator:
    """THE generator of a chunk's task: seeded by the study's seed and the chunk's index only
    (`SeedSequence(seed, spawn_key=(index,))`), so the draws do not depend on where or when it runs."""
    return np.random.default_rng(np.random.SeedSequence(chunk.seed, spawn_key=(chunk.index,)))


def check_scheduler_address(address: str) -> str:
    """`address` if it names a Dask scheduler as tcp://HOST:PORT or tls://HOST:PORT; ValueError otherwise."""
    scheme, sep, rest = address.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or scheme not in ("tcp", "tls") or not colon or not host or not port.isdigit():
        raise ValueError(f"scheduler address {address!r}: expected tcp://HOST:PORT or tls://HOST:PORT "
                         "(e.g. tcp://127.0.0.1:8786)")
    return address


def run_chunks(task: Callable[[Chunk], object], chunks: Iterable[Chunk], *, workers: int | None = None,
               scheduler: str | None = None, on_result: OnResult | None = None) -> tuple[list, RunInfo]:
    """`task(chunk)` for every chunk, on Dask: the results in chunk order, and how the cluster ran.

    `on_result(chunk, result, done, total)` is called in this process as each chunk finishes (in the order
    they finish). Without `scheduler`, a LocalCluster of `workers` (default: os.cpu_count()) single-threaded
    processes on 127.0.0.1 runs them and is closed at the end; with it, the cluster there does (`workers`
    must then be None). A task's exception is raised here; an exception or KeyboardInterrupt cancels the
    chunks not yet done. Before the chunks are submitted, every worker must load the task and a chunk (a
    worker that cannot unpickle a task would otherwise leave the run waiting for ever): RuntimeError if one
    cannot — the workers need sharedctl installed, at the version installed here.
    """
    chunks = sorted(chunks, key=lambda c: c.index)
    if len({c.index for c in chunks}) != len(chunks):
        raise ValueError("run_chunks: two chunks share an index")
    if scheduler is not None:
        check_scheduler_address(scheduler)
        if workers is not None:
            raise ValueError("run_chunks: workers sizes the local cluster; a scheduler's cluster has its own")
    elif workers is not None and workers < 1:
        raise ValueError(f"run_chunks: workers must be at least 1, got {workers}")
    distributed = _import_distributed()
    if not chunks:
        return [], RunInfo(workers=0, startup_seconds=0.0, wall_seconds=0.0)
    start = time.monotonic()
    results: dict[int, object] = {}
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            cluster = stack.enter_context(_local_cluster(distributed, workers or os.cpu_count() or 1))
            client = stack.enter_context(distributed.Client(cluster))
        else:
            client = stack.enter_context(distributed.Client(scheduler, timeout=CONNECT_TIMEOUT_S))
            _wait_for_a_worker(client, scheduler)
        _check_the_workers_load(client, task, chunks[0], scheduler or "the local cluster")
        info_workers = len(client.nthreads())     # every worker (scheduler_info() may list only a few)
        startup = time.monotonic() - start
        futures = client.map(task, chunks, pure=False)
        chunk_of = {future.key: chunk for future, chunk in zip(futures, chunks)}
        try:
            for done, future in enumerate(distributed.as_completed(futures), start=1):
                chunk = chunk_of[future.key]
                results[chunk.index] = future.result()
                if on_result is not None:
                    on_result(chunk, results[chunk.index], done, len(chunks))
        except BaseException:
            with contextlib.suppress(Exception):   # a cluster already broken: the error being raised says why
                client.cancel(futures)
            raise
    ordered = [results[c.index] for c in chunks]
    return ordered, RunInfo(workers=info_workers, startup_seconds=startup, wall_seconds=time.monotonic() - start)


def _import_distributed():
    try:
        import distributed
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(
            f"sharedctl faults montecarlo needs dask.distributed (could not import {exc.name!r}), which comes "
            "with the 'montecarlo' extra: pip install 'sharedctl[montecarlo]'", name=exc.name) from exc
    return distributed


@contextlib.contextmanager
def _local_cluster(distributed, workers: int):
    """A LocalCluster of `workers` single-threaded processes on this machine, closed on leaving.

    * Every socket binds 127.0.0.1, and the comms are mutual TLS with throwaway certificates (`security=True`:
      a CA and keys made for this cluster), so another local user can neither connect nor submit code.
    * No dashboard; the HTTP server the scheduler and the workers open anyway binds a free loopback port
      (not the well-known 8787) and serves no route.
    * The scratch space, which Dask also puts first on the workers' sys.path, is a private temporary
      directory removed on leaving, not the shared /tmp/dask-scratch-space another user could create first.
    * The nannies put `distributed.nanny.pre-spawn-environ` into this process's os.environ before spawning
      a worker (numpy's thread pools are sized when numpy is imported there); the variables they set here
      are put back as they were when the cluster is closed.
    """
    import dask

    scratch = tempfile.TemporaryDirectory(prefix="sharedctl-montecarlo-", ignore_cleanup_errors=True)
    config = {f"distributed.nanny.pre-spawn-environ.{name}": value for name, value in SINGLE_THREADED.items()}
    config.update({"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": [],
                   "temporary-directory": scratch.name})
    with scratch, dask.config.set(config):
        touched = set(dask.config.get("distributed.nanny.pre-spawn-environ")) | {"PYTHONHASHSEED"}
        before = {name: os.environ.get(name) for name in touched}
        try:
            with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                          dashboard_address=None, security=True,
                                          scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as cluster:
                yield cluster
        finally:
            for name, value in before.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value


def _check_the_workers_load(client, task: Callable, chunk: Chunk, where: str) -> None:
    """RuntimeError naming the worker and why, unless every worker can unpickle (task, chunk) as Dask will send
    them. The workers run the standard library's pickle.loads on the bytes, so this check needs nothing there."""
    import pickle

    from distributed.protocol import pickle as dask_pickle

    outcome = client.run(pickle.loads, dask_pickle.dumps((task, chunk)), on_error="return")
    failed = {worker: result for worker, result in outcome.items() if isinstance(result, BaseException)}
    if failed:
        worker, exc = sorted(failed.items())[0]
        name = f"{getattr(task, '__module__', '?')}.{getattr(task, '__qualname__', task)}"
        raise RuntimeError(f"{len(failed)} worker(s) of {where} cannot load the task {name} ({worker}: {exc!r}); "
                           "the workers need sharedctl installed, at the version installed here") from exc


def _wait_for_a_worker(client, scheduler: str) -> None:
    try:
        client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
    except TimeoutError as exc:
        raise TimeoutError(f"scheduler {scheduler} has had no worker for {WORKERS_TIMEOUT_S} s") from exc
