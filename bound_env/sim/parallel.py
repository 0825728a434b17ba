"""Executors for embarrassingly parallel work: in-process, a local process pool, or Dask.

Everything that fans out tasks (margins, compare, sweep, basin-map, multi-seed training)
sees only a `concurrent.futures`-style executor (``submit`` returning futures) built here
from the command line's ``--scheduler`` and ``--workers``:

| ``--scheduler`` | executor |
| --- | --- |
| (none), ``--workers 1`` | `SerialExecutor`: each task runs at submit time, in this process |
| (none), ``--workers N`` | `RestartingProcessPool`: N worker processes (no Dask) |
| ``local`` (``local:N``) | `distributed.LocalCluster`: one 1-thread worker process per core (N) |
| ``tcp://HOST:PORT`` | a `distributed.Client` connected to a running ``dask scheduler`` |

Dask is an optional extra (``pip install -e ".[dask]"``); only the last two rows import it.
A Dask worker that dies (e.g. SIGKILL) has its tasks rescheduled on the other workers by the
scheduler (``distributed.scheduler.allowed-failures``, 3 by default). The local process pool
does the same: when a worker process dies (SIGKILL, the OOM killer), `RestartingProcessPool`
starts a new pool and resubmits the unfinished tasks (at most ``MAX_RESTARTS`` times per
run; after that they fail with ``BrokenProcessPool``). `run_tasks` reports a task that raises
with its key and arguments and carries on with the others.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import sys
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

DASK_HINT = 'pip install -e ".[dask]"'
LOCAL = "local"
CONNECT_TIMEOUT_S = 20  # connecting to a remote scheduler
MAX_WORKERS = 256  # --workers and 'local:N' alike
MAX_RESTARTS = 3  # new pools after a dead worker, per run (Dask's allowed-failures is 3 too)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread (`on_sigterm`) so that it unwinds as Ctrl-C does:
    pools are shut down and their workers stopped (`open_pool`), and the command ends with one
    line (`bound_env.commands.cli.main`)."""


def _raise_terminated(signum, frame):
    raise Terminated()


def on_sigterm():
    """Make SIGTERM raise `Terminated` in this (main) thread; returns a function that puts
    the previous handler back. Nothing is changed outside the main thread."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    return lambda: signal.signal(signal.SIGTERM, previous)


def _worker_init() -> None:
    """In each worker process of `RestartingProcessPool`: Ctrl-C is the parent's to handle
    (the terminal sends it to the whole process group) and SIGTERM ends the worker at once."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


class SerialExecutor(cf.Executor):
    """Runs each task at submit time, in this process (``--workers 1``)."""

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as e:  # noqa: BLE001 - delivered through the future
            fut.set_exception(e)
        return fut


class RestartingProcessPool(cf.Executor):
    """A `concurrent.futures.ProcessPoolExecutor` of ``workers`` processes that survives a
    dead worker. A killed worker breaks a ProcessPoolExecutor for good (every unfinished
    future raises ``BrokenProcessPool``); here a new pool is started instead and every task
    that was unfinished is submitted to it again, so a task's future gets its result as if
    nothing happened (tasks are functions of their arguments). After ``max_restarts`` new
    pools the next break is final: the unfinished futures raise ``BrokenProcessPool``."""

    def __init__(self, workers: int, max_restarts: int = MAX_RESTARTS):
        self.workers, self.max_restarts = int(workers), int(max_restarts)
        self.restarts = 0
        self._lock = threading.Lock()
        self._pool = self._new_pool()
        self._generation = 0
        self._closed = False

    def submit(self, fn, /, *args, **kwargs):
        outer = cf.Future()
        self._submit(outer, fn, args, kwargs)
        return outer

    def _submit(self, outer, fn, args, kwargs) -> None:
        while True:
            with self._lock:
                if self._closed:
                    raise RuntimeError("cannot submit to a pool that was shut down")
                pool, generation = self._pool, self._generation
            try:
                inner = pool.submit(fn, *args, **kwargs)
                break
            except BrokenProcessPool as e:  # broke before this task reached it
                if not self._restart(generation):
                    _settle(outer, exc=e)
                    return

        def done(f):
            if f.cancelled():
                outer.cancel()
                return
            exc = f.exception()
            if isinstance(exc, BrokenProcessPool) and self._restart(generation):
                try:
                    self._submit(outer, fn, args, kwargs)
                except RuntimeError as e:  # shut down meanwhile
                    _settle(outer, exc=e)
            else:
                if isinstance(exc, BrokenProcessPool):
                    exc = BrokenProcessPool(f"{exc} (after {self.restarts} restarts of the pool)")
                _settle(outer, exc=exc, result=None if exc is not None else f.result())

        inner.add_done_callback(done)

    def _restart(self, generation: int) -> bool:
        """Replace the pool that broke in ``generation`` (once, whichever task notices it
        first); False when the restarts are used up or the pool was shut down."""
        with self._lock:
            if self._closed:
                return False
            if generation != self._generation:
                return True  # replaced already
            if self.restarts >= self.max_restarts:
                return False
            old = self._pool
            self._pool = self._new_pool()
            self._generation += 1
            self.restarts += 1
        old.shutdown(wait=False, cancel_futures=True)
        print(
            f"[parallel] a worker process died: restarted the pool ({self.workers} workers, "
            f"restart {self.restarts} of at most {self.max_restarts}) and resubmitted its "
            "unfinished tasks",
            file=sys.stderr,
            flush=True,
        )
        return True

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(self.workers, initializer=_worker_init)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._lock:
            self._closed = True
            pool = self._pool
        pool.shutdown(wait=wait, cancel_futures=cancel_futures)

    def terminate(self, timeout: float = 5.0) -> None:
        """Stop now (an interrupted run): cancel what has not started and end the worker
        processes (SIGTERM, then SIGKILL after ``timeout`` s) rather than wait for their tasks."""
        with self._lock:
            self._closed = True
            pool = self._pool
        # the executor keeps its processes in `_processes` (pid -> Process); there is no
        # public way to stop a running task
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            with contextlib.suppress(Exception):
                p.terminate()
        for p in procs:
            with contextlib.suppress(Exception):
                p.join(timeout)
                if p.is_alive():
                    p.kill()
                    p.join(timeout)


def _settle(fut: cf.Future, exc=None, result=None) -> None:
    """Finish ``fut`` unless it was cancelled meanwhile (``run_tasks`` cancels what is left)."""
    try:
        if exc is not None:
            fut.set_exception(exc)
        else:
            fut.set_result(result)
    except cf.InvalidStateError:
        pass


def cpu_count() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def add_scheduler_args(p, workers_default: int | None = 2) -> None:
    """``--scheduler`` (and ``--workers`` unless ``workers_default`` is None) on a parser."""
    p.add_argument(
        "--scheduler",
        metavar="local|tcp://HOST:PORT",
        help="run the tasks on Dask: 'local' starts a LocalCluster with one worker "
        "process per core ('local:N': N workers), tcp://HOST:PORT connects to a "
        f"running scheduler (needs {DASK_HINT}); default: a local process pool",
    )
    if workers_default is not None:
        from ..files.values import number

        p.add_argument(
            "--workers",
            type=number(int, 1, MAX_WORKERS),
            default=workers_default,
            help="worker processes of the local pool, without --scheduler (default: %(default)s)",
        )


def check_scheduler(scheduler: str | None) -> None:
    """ValueError unless ``scheduler`` is None, ``local``, ``local:N`` or an address."""
    if scheduler is None:
        return
    if scheduler == LOCAL:
        return
    if scheduler.startswith(LOCAL + ":"):
        n = scheduler.split(":", 1)[1]
        if not n.isdigit() or not 1 <= int(n) <= MAX_WORKERS:
            raise ValueError(
                f"--scheduler {scheduler!r}: 'local:N' needs 1 <= N <= {MAX_WORKERS} workers"
            )
        return
    if "://" not in scheduler or not scheduler.split("://", 1)[1]:
        raise ValueError(
            f"--scheduler must be 'local', 'local:N' or an address like "
            f"tcp://HOST:PORT, got {scheduler!r}"
        )


def check_listening(scheduler: str, timeout: float = 5.0) -> None:
    """ValueError naming ``--scheduler`` at once when nothing listens at a ``tcp://`` address
    (connection refused, an unknown host, a bad port), instead of Dask's retries for
    `CONNECT_TIMEOUT_S`; other schemes are left to Dask."""
    import socket
    from urllib.parse import urlsplit

    if not scheduler.startswith("tcp://"):
        return
    try:
        parts = urlsplit(scheduler)
        host, port = parts.hostname, parts.port or 8786  # Dask's default port
    except ValueError as e:  # a port that is not a number or out of range
        raise ValueError(f"--scheduler {scheduler}: not an address ({e})") from None
    if not host:
        raise ValueError(f"--scheduler {scheduler}: no host (tcp://HOST:PORT)")
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except ConnectionRefusedError:
        raise ValueError(
            f"--scheduler {scheduler}: connection refused (no scheduler listens on "
            f"{host}:{port}; start one with `dask scheduler`)"
        ) from None
    except socket.gaierror as e:
        raise ValueError(f"--scheduler {scheduler}: unknown host {host!r} ({e})") from None
    except OSError:
        return  # a timeout or a firewall: Dask tries for CONNECT_TIMEOUT_S and says so


def _import_distributed():
    try:
        import distributed
    except ModuleNotFoundError:
        raise ValueError(
            f"--scheduler needs Dask distributed, which is not installed: {DASK_HINT}"
        ) from None
    return distributed


def _has_dashboard() -> bool:
    try:
        import bokeh  # noqa: F401 - the Dask dashboard needs it
    except ModuleNotFoundError:
        return False
    return True


@dataclass
class Pool:
    """An executor and what to say about it (``describe``)."""

    executor: cf.Executor
    kind: str  # "serial", "processes", "dask"
    workers: int
    dashboard: str | None = None
    address: str | None = None
    client: object = None

    def describe(self) -> str:
        if self.kind == "serial":
            return "in this process"
        if self.kind == "processes":
            return f"local process pool, {self.workers} workers"
        text = f"Dask scheduler {self.address}, {self.workers} workers"
        return text + (f", dashboard {self.dashboard}" if self.dashboard else "")


@contextlib.contextmanager
def open_pool(scheduler: str | None = None, workers: int = 1, quiet: bool = False):
    """The executor for ``--scheduler`` / ``--workers`` (see the module docstring); shut
    down (cluster included) on leaving the block. Prints where the tasks run (and the Dask
    dashboard link when there is one) to stderr unless ``quiet``."""
    check_scheduler(scheduler)
    if scheduler is None:
        if not 1 <= int(workers) <= MAX_WORKERS:
            raise ValueError(f"--workers must be from 1 to {MAX_WORKERS}, got {workers}")
        if workers == 1:
            yield Pool(SerialExecutor(), "serial", 1)
            return
        ex = RestartingProcessPool(int(workers))
        try:
            yield Pool(ex, "processes", int(workers))
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM (`Terminated`): no waiting for tasks
            ex.terminate()
            raise
        finally:
            ex.shutdown(wait=True, cancel_futures=True)
        return
    distributed = _import_distributed()
    cluster = None
    if not scheduler.startswith(LOCAL):
        check_listening(scheduler)  # a refused port fails now, not after CONNECT_TIMEOUT_S
    with contextlib.ExitStack() as stack:
        if scheduler.startswith(LOCAL):
            n = int(scheduler.split(":", 1)[1]) if ":" in scheduler else cpu_count()
            cluster = stack.enter_context(
                distributed.LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=":0",  # a free port: other clusters may run beside
                )
            )
            client = stack.enter_context(distributed.Client(cluster))
        else:
            try:
                client = distributed.Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
            except (OSError, TimeoutError, ValueError, TypeError) as e:
                raise ValueError(f"--scheduler {scheduler}: cannot connect ({e})") from None
            stack.callback(client.close)
        info = client.scheduler_info()
        n = len(info.get("workers", {}))
        served = "dashboard" in info.get("services", {}) and _has_dashboard()
        pool = Pool(
            client.get_executor(pure=False),
            "dask",
            n,
            dashboard=client.dashboard_link if served else None,
            address=client.scheduler.address,
            client=client,
        )
        if not quiet:
            print(f"[parallel] {pool.describe()}", file=sys.stderr, flush=True)
        yield pool


class TasksFailed(RuntimeError):
    """Some tasks of a run failed (each was reported as it failed); the others completed."""

    def __init__(self, failures: list, total: int, hint: str = ""):
        self.failures = failures
        first = failures[0]
        super().__init__(f"{len(failures)} of {total} tasks failed (first: {first}){hint}")


@dataclass
class TaskFailure:
    """A task that raised (or whose workers kept dying): its key, arguments and error."""

    key: str
    args: tuple
    error: str

    def __str__(self) -> str:
        return f"task {self.key} {self.args!r}: {self.error}"


class ProgressLines:
    """Progress for a stderr that is not a terminal (a log file, a pipe): one line such as
    ``[margins lqr] 12/40 tasks (30 %), 95 s`` every `EVERY_S` seconds or every `EVERY_FRACTION`
    of the tasks, whichever comes first, and one at the end. The interface of the tqdm bar
    that `run_tasks` uses (``update``, ``write``, ``close``)."""

    EVERY_S = 30.0
    EVERY_FRACTION = 0.1

    def __init__(self, total: int, done: int = 0, desc: str = ""):
        self.total, self.done, self.desc = total, done, desc or "tasks"
        self.t0 = self.last_t = time.perf_counter()
        self.last_done = done
        self._line()

    def _line(self) -> None:
        pct = 100.0 * self.done / self.total if self.total else 100.0
        elapsed = time.perf_counter() - self.t0
        print(
            f"[{self.desc}] {self.done}/{self.total} tasks ({pct:.0f} %), {elapsed:.0f} s",
            file=sys.stderr,
            flush=True,
        )
        self.last_t, self.last_done = time.perf_counter(), self.done

    def update(self, n: int = 1) -> None:
        self.done += n
        step = max(1, int(self.EVERY_FRACTION * self.total))
        due = time.perf_counter() - self.last_t >= self.EVERY_S
        if due or self.done - self.last_done >= step or self.done == self.total:
            self._line()

    def write(self, msg: str, file=None) -> None:
        print(msg, file=file or sys.stderr, flush=True)

    def close(self) -> None:
        if self.done != self.last_done:
            self._line()


def run_tasks(
    executor,
    tasks: dict,
    progress: bool = False,
    desc: str = "",
    on_result=None,
    done_before: int = 0,
) -> tuple[dict, list[TaskFailure]]:
    """Submit every ``{key: (fn, args)}`` (or ``(fn, args, shown)``: ``shown`` is what a
    failure reports instead of ``args``) and collect the results as they complete.

    ``on_result(key, result)`` runs in this process for each result as it arrives (e.g. a
    cache write, so that an interrupted run resumes). One progress bar counts completed
    tasks (``done_before`` of them already done, e.g. cached). A task that raises does not
    stop the others: it is printed to stderr with its key and arguments and returned in the
    list of failures. Returns (results by key, failures)."""
    results: dict = {}
    failures: list[TaskFailure] = []
    if not tasks:
        return results, failures
    bar = None
    if progress and sys.stderr.isatty():
        from tqdm.auto import tqdm

        bar = tqdm(
            total=len(tasks) + done_before, initial=done_before, desc=desc or None, file=sys.stderr
        )
    elif progress:  # a log file: a line now and then, not a bar redrawn in place
        bar = ProgressLines(len(tasks) + done_before, done_before, desc)
    pending = {}
    try:
        for key, (fn, args, *_) in tasks.items():
            pending[executor.submit(fn, *args)] = key
        for fut in cf.as_completed(pending):
            key = pending[fut]
            try:
                res = fut.result()
            except Exception as e:  # noqa: BLE001 - reported, the run goes on
                shown = tasks[key][2] if len(tasks[key]) > 2 else tasks[key][1]
                fail = TaskFailure(key, shown, f"{type(e).__name__}: {e}")
                failures.append(fail)
                msg = f"[{desc or 'tasks'}] failed: {fail}"
                (
                    bar.write(msg, file=sys.stderr)
                    if bar is not None
                    else print(msg, file=sys.stderr, flush=True)
                )
            else:
                results[key] = res
                if on_result is not None:
                    on_result(key, res)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        for fut in pending:
            fut.cancel()
    return results, failures
