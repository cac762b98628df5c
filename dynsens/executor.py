"""Where independent simulations run: in this process, in local worker processes, or on Dask.

Every embarrassingly parallel job of dynsens (optimization starts, finite-difference
columns, the Δt × method ladder, design studies) goes through one :class:`Executor`:

* ``SerialExecutor`` — in this process, one task after the other (``--workers 1``);
* ``ProcessExecutor`` — local worker processes started with the ``spawn`` method (a fresh
  interpreter: no inherited threads, locks or open HDF5 handles, the same on every OS);
* ``DaskExecutor`` — tasks on a Dask distributed scheduler (``--scheduler ADDRESS``), one
  machine or many; every worker needs the same dynsens installed (functions travel by name).

Tasks are module-level functions of one picklable argument; results come back to the
calling process in completion order, where only the caller writes files.  A task may
:func:`publish` small messages (plain Python objects) while it runs; they reach the
caller's ``on_message`` in the order the task sent them (optimization rows stream this way).
"""
from __future__ import annotations

import multiprocessing as mp
import os
import queue as _queue
import threading
import uuid
from collections import OrderedDict
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, Callable, Sequence

from .errors import DynsensError

Task = Callable[[Any], Any]
OnResult = Callable[[int, Any], None]
OnMessage = Callable[[Any], None]

_POLL = 0.05          # s, how long the caller waits for a message before looking at the futures


class ExecutorError(DynsensError, RuntimeError):
    """The scheduler cannot be reached, or Dask is not installed."""


# --------------------------------------------------------------------------------------
# worker side
# --------------------------------------------------------------------------------------
_CHANNEL: OnMessage | None = None
_CASES: "OrderedDict[tuple[str, str], Any]" = OrderedDict()
_CASE_CACHE_SIZE = 8
# A Dask worker may run several tasks in threads of one process (``--nthreads > 1`` or a
# LocalCluster with processes=False).  Simulations hold the GIL anyway, and the compiled
# kernel keeps per-process work buffers, so one simulation at a time per process.
_RUN_LOCK = threading.Lock()


def publish(message: Any) -> None:
    """Send ``message`` (plain Python data) from a running task to the caller's ``on_message``."""
    if _CHANNEL is not None:
        _CHANNEL(message)


def cached_case(text: str, source: str) -> Any:
    """The case parsed from its YAML ``text``, cached per worker process (cases travel as text)."""
    from .case.load_cases import load_any_text
    key = (text, source)
    case = _CASES.get(key)
    if case is None:
        case = load_any_text(text, source)
        _CASES[key] = case
        while len(_CASES) > _CASE_CACHE_SIZE:
            _CASES.popitem(last=False)
    else:
        _CASES.move_to_end(key)
    return case


def remember_case(case: Any) -> None:
    """Put an already loaded case into this process's cache (saves re-parsing in-process)."""
    _CASES[(case.text, case.source)] = case


def _init_process(channel: Any) -> None:
    global _CHANNEL
    _CHANNEL = channel.put


def _dask_call(fn: Task, arg: Any, topic: str) -> Any:
    global _CHANNEL
    from distributed import get_worker
    worker = get_worker()
    with _RUN_LOCK:
        _CHANNEL = lambda msg: worker.log_event(topic, msg)  # noqa: E731
        try:
            return fn(arg)
        finally:
            _CHANNEL = None


# --------------------------------------------------------------------------------------
# caller side
# --------------------------------------------------------------------------------------
class Executor:
    """Runs tasks and hands their results to the caller as they finish."""

    workers: int = 1
    description: str = ""

    def run(self, fn: Task, args: Sequence[Any], on_result: OnResult,
            on_message: OnMessage | None = None) -> None:
        """Call ``fn(args[i])`` for every i; ``on_result(i, result)`` in this process, in completion order.

        A task that raises stops the run: the other tasks are cancelled and the exception
        is raised here (tasks that should not stop a run catch their own errors).
        """
        raise NotImplementedError

    def map(self, fn: Task, args: Sequence[Any], done: Callable[[int], None] | None = None) -> list[Any]:
        """Results of ``fn`` over ``args`` in the order of ``args``; ``done(i)`` is called as each
        task finishes (progress)."""
        out: list[Any] = [None] * len(args)

        def keep(i: int, r: Any) -> None:
            out[i] = r
            if done is not None:
                done(i)
        self.run(fn, args, keep)
        return out

    def close(self) -> None:
        """Release workers or the connection."""

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class SerialExecutor(Executor):
    """In this process, one task after the other."""

    description = "this process"

    def run(self, fn: Task, args: Sequence[Any], on_result: OnResult,
            on_message: OnMessage | None = None) -> None:
        global _CHANNEL
        previous = _CHANNEL
        _CHANNEL = on_message
        try:
            for i, a in enumerate(args):
                on_result(i, fn(a))
        finally:
            _CHANNEL = previous


def _drain(messages: "_queue.Queue[Any] | Any", futures: dict[Any, int], on_result: OnResult,
           on_message: OnMessage | None) -> None:
    """Deliver messages while waiting; results as their futures finish."""
    left = dict(futures)
    while left:
        try:
            msg = messages.get(timeout=_POLL)
            if on_message is not None:
                on_message(msg)
            continue
        except _queue.Empty:
            pass
        for fu in [fu for fu in left if fu.done()]:
            i = left.pop(fu)
            on_result(i, fu.result())


class ProcessExecutor(Executor):
    """Local worker processes, started with ``spawn`` (created on first use, kept until close)."""

    def __init__(self, workers: int) -> None:
        self.workers = int(workers)
        self.description = f"{self.workers} local processes"
        self._ctx = mp.get_context("spawn")
        self._pool: ProcessPoolExecutor | None = None
        self._messages: Any = None

    def _ensure_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._messages = self._ctx.Queue()
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=self._ctx,
                                             initializer=_init_process, initargs=(self._messages,))
        return self._pool

    def run(self, fn: Task, args: Sequence[Any], on_result: OnResult,
            on_message: OnMessage | None = None) -> None:
        pool = self._ensure_pool()
        futures: dict[Future, int] = {}
        try:
            for i, a in enumerate(args):
                futures[pool.submit(fn, a)] = i
            _drain(self._messages, futures, on_result, on_message)
        except BaseException:
            self._terminate()
            raise

    def _terminate(self) -> None:
        """Stop our own worker processes at once (the caller was interrupted or failed)."""
        if self._pool is None:
            return
        procs = list(getattr(self._pool, "_processes", {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


class DaskExecutor(Executor):
    """Tasks on a Dask distributed scheduler; messages travel as worker events."""

    def __init__(self, address: str, timeout: float = 30.0) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ExecutorError("--scheduler needs Dask distributed: pip install 'dynsens[dask]'") from None
        try:
            self._client = Client(address, timeout=timeout)
        except (OSError, TimeoutError, ValueError) as exc:     # ValueError: not an address
            raise ExecutorError(f"--scheduler {address}: cannot connect ({exc})") from None
        n = len(self._client.scheduler_info().get("workers", {}))
        self.workers = max(n, 1)
        self.description = f"Dask scheduler {address} ({n} workers)"

    def run(self, fn: Task, args: Sequence[Any], on_result: OnResult,
            on_message: OnMessage | None = None) -> None:
        topic = f"dynsens-{uuid.uuid4().hex}"
        messages: _queue.Queue = _queue.Queue()
        self._client.subscribe_topic(topic, lambda ev: messages.put(ev[1]))
        futures: dict[Any, int] = {}
        try:
            for i, a in enumerate(args):
                futures[self._client.submit(_dask_call, fn, a, topic, pure=False)] = i
            _drain(messages, futures, on_result, on_message)
        except BaseException:
            self._client.cancel(list(futures))
            raise
        finally:
            self._client.unsubscribe_topic(topic)

    def close(self) -> None:
        self._client.close()


def make_executor(workers: int | None = None, scheduler: str | None = None, *, tasks: int | None = None,
                  default_workers: int | None = None) -> Executor:
    """The executor for ``--workers``/``--scheduler``.

    Parameters
    ----------
    workers : local worker processes; 1 runs in this process.  Default ``default_workers``,
        else the number of CPUs.  Ignored with ``scheduler``.
    scheduler : address of a Dask distributed scheduler, e.g. ``tcp://10.0.0.5:8786``.
    tasks : number of tasks to come, when known: no more processes than tasks are started.
    """
    if scheduler:
        return DaskExecutor(scheduler)
    n = int(workers or default_workers or os.cpu_count() or 1)
    if n < 1:
        raise ExecutorError(f"--workers must be >= 1, found {n}")
    if tasks is not None:
        n = min(n, max(int(tasks), 1))
    return ProcessExecutor(n) if n > 1 else SerialExecutor()
