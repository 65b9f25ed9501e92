"""Where runs are executed, and the driver side that submits them (:class:`Evaluator`).

Runs go to a ``concurrent.futures`` executor (:func:`open_executor`): a local
``ProcessPoolExecutor`` (spawn, ``max_workers``) by default, ``executor="serial"`` to run in
this process, any ``concurrent.futures.Executor``, or a Dask ``distributed.Client`` (its
``get_executor(pure=False)`` is used). The process pool starts its workers with 'spawn' (a
forked OpenMP runtime can hang), so a script that calls :func:`pelletdem.search.scan`,
:func:`pelletdem.search.fit` or :func:`pelletdem.variants.calibrate_variants` with it must
keep its work under ``if __name__ == "__main__":`` (:func:`check_main_guard` says so before
any worker starts, rather than letting each worker re-run the script); a worker that dies is replaced, and its
point retried once on its own. The :class:`Evaluator` serves cached runs, never runs a key
twice and writes the run cache (:class:`pelletdem.run_cache.RunCache`) itself, so Dask
workers need no shared file system (``relaxed_dir`` does need one).
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import dataclasses
import multiprocessing
import os
import queue
import threading
import time
import warnings
from typing import Callable, Dict, List, Optional, Sequence

from .run_cache import RunCache
from .runs import RunSpec, canonical
from .worker import run_point

__all__ = ["open_executor", "worker_count", "stroke_plan", "with_relaxed_dir", "Evaluator", "unguarded_main_line",
           "check_main_guard"]


#: How often (s) a worker looks whether the process that started it is still there.
PARENT_POLL_S = 1.0


def _exit_with_parent(parent: int) -> None:
    """Worker initializer: a daemon thread ends this worker (exit status 3) once the process
    ``parent`` that started it is gone. A driver killed by a signal on its own process (not
    its process group) runs no shutdown, and its workers would otherwise compute on for as
    long as their runs take (the engine releases the GIL while it steps, so the thread is
    heard within a second)."""
    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(3)

    threading.Thread(target=watch, name="pelletdem-parent-watch", daemon=True).start()


def _process_pool(n: int, context) -> cf.ProcessPoolExecutor:
    """A process pool of ``n`` workers started by ``context`` that end with this process."""
    return cf.ProcessPoolExecutor(max_workers=n, mp_context=context, initializer=_exit_with_parent,
                                  initargs=(os.getpid(),))


def _is_main_guard(test) -> bool:
    import ast

    if not (isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = [test.left, test.comparators[0]]
    names = [x for x in sides if isinstance(x, ast.Name) and x.id == "__name__"]
    consts = [x for x in sides if isinstance(x, ast.Constant) and x.value == "__main__"]
    return len(names) == 1 and len(consts) == 1


# When this module was first imported (s since the epoch), a lower bound on when the running
# script started that is good enough to tell whether the file has been edited since.
_IMPORTED_AT = time.time()


def unguarded_main_line() -> Optional[int]:
    """The line of the running script (``__main__``, a file) from which this call came, when
    that line runs at the script's top level outside ``if __name__ == "__main__":``; None
    otherwise (called from a function, under the guard, interactively or from a notebook).
    A spawned worker re-runs such a line on import, and would start workers of its own."""
    import ast
    import sys

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if not path or not os.path.isfile(path):
        return None
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "<module>" and frame.f_globals.get("__name__") == "__main__":
            break
        frame = frame.f_back
    if frame is None or os.path.abspath(frame.f_code.co_filename) != os.path.abspath(path):
        return None
    line = frame.f_lineno
    try:
        if os.path.getmtime(path) > _IMPORTED_AT:
            return None  # the script was edited while it runs: its line numbers are not the file's
        with open(path, encoding="utf-8") as fh:
            tree = ast.parse(fh.read(), path)
    except (OSError, SyntaxError, ValueError):
        return None
    for node in tree.body:
        if isinstance(node, ast.If) and _is_main_guard(node.test) and node.lineno <= line <= (node.end_lineno or line):
            return None
    return line


def check_main_guard() -> None:
    """RuntimeError, before any worker starts, when worker processes would be started from a
    script's top level (see :func:`unguarded_main_line`), saying what to do instead."""
    import sys

    line = unguarded_main_line()
    if line is not None:
        path = sys.modules["__main__"].__file__
        raise RuntimeError(
            f"{path}, line {line}: worker processes are started from the script's top level. Each worker "
            "imports the script again and would run its work (and start workers) again. Put the script's "
            "work in a function called under `if __name__ == \"__main__\":`, or run without worker "
            "processes (executor=\"serial\").")


class _SerialExecutor(cf.Executor):
    """Runs each call at submit, in the calling thread, one at a time."""

    _lock = threading.Lock()

    def submit(self, fn, *args, **kwargs):
        fut = cf.Future()
        with self._lock:
            try:
                fut.set_result(fn(*args, **kwargs))
            except BaseException as e:  # noqa: BLE001 (handed to the future)
                fut.set_exception(e)
        return fut


def _is_dask_client(obj) -> bool:
    return type(obj).__module__.startswith("distributed") and hasattr(obj, "get_executor")


class _RespawningPool(cf.Executor):
    """A process pool that survives its workers: when one dies the pool is broken (every
    pending future fails with BrokenProcessPool and submit refuses), so the next submit gets a
    fresh pool of the same size. ``submit_isolated`` runs a call alone in a one-worker pool of
    its own (at most ``max_workers`` at a time): a retried point that kills its worker again
    then takes no other point down with it."""

    def __init__(self, pool: cf.ProcessPoolExecutor, own: bool):
        self._pool, self._own = pool, own
        self._max_workers = getattr(pool, "_max_workers", None) or os.cpu_count() or 1
        self._mp_context = getattr(pool, "_mp_context", None) or multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._made: List[cf.ProcessPoolExecutor] = []  # replacement pools, shut down with us
        self._queue: List[tuple] = []
        self._running = 0
        self._isolated: set = set()

    def submit(self, fn, *args, **kwargs):
        with self._lock:
            pool = self._pool
        try:
            return pool.submit(fn, *args, **kwargs)
        except cf.BrokenExecutor:
            with self._lock:
                if self._pool is pool:
                    self._pool = _process_pool(self._max_workers, self._mp_context)
                    self._made.append(self._pool)
                pool = self._pool
            return pool.submit(fn, *args, **kwargs)

    def submit_isolated(self, fn, *args) -> cf.Future:
        out = cf.Future()
        with self._lock:
            self._queue.append((fn, args, out))
        self._pump()
        return out

    def _pump(self) -> None:
        while True:
            with self._lock:
                if not self._queue or self._running >= self._max_workers:
                    return
                fn, args, out = self._queue.pop(0)
                self._running += 1
                pool = _process_pool(1, self._mp_context)
                self._isolated.add(pool)
            try:
                inner = pool.submit(fn, *args)
            except BaseException as e:  # noqa: BLE001 (handed to the future)
                self._isolated_done(None, pool, out, e)
                continue
            inner.add_done_callback(lambda f, pool=pool, out=out: self._isolated_done(f, pool, out))

    def _isolated_done(self, f, pool, out: cf.Future, error=None) -> None:
        # Called in the pool's own manager thread: shut it down without waiting for itself.
        pool.shutdown(wait=False)
        with self._lock:
            self._running -= 1
            self._isolated.discard(pool)
        try:
            if error is None:
                error = f.exception()
            if error is None:
                out.set_result(f.result())
            else:
                out.set_exception(error)
        except cf.InvalidStateError:  # cancelled meanwhile
            pass
        self._pump()

    def shutdown(self, wait=True, *, cancel_futures=False):
        with self._lock:
            pools = list(self._made) + list(self._isolated) + ([self._pool] if self._own else [])
            for _, _, out in self._queue:
                out.cancel()
            self._queue.clear()
        for pool in pools:
            pool.shutdown(wait=wait, cancel_futures=cancel_futures)


@contextlib.contextmanager
def open_executor(executor, max_workers: Optional[int]):
    """A context manager yielding the executor runs are submitted to, shut down on exit when
    it is ours. ``executor``: None (a spawn process pool of ``max_workers``, default the CPU
    count, that replaces workers which die), a ``ProcessPoolExecutor`` (the caller's, wrapped
    the same way and left running), 'serial' (each run at submit, in the calling thread), a
    Dask ``distributed.Client`` or any object with ``submit``. ValueError for anything else."""
    if executor is None:
        n = max_workers or os.cpu_count() or 1
        if not isinstance(n, int) or n < 1:
            raise ValueError(f"max_workers = {max_workers!r} must be an integer >= 1")
        check_main_guard()
        ex = _RespawningPool(_process_pool(n, multiprocessing.get_context("spawn")), own=True)
        try:
            yield ex
        finally:
            ex.shutdown(wait=True, cancel_futures=True)
    elif isinstance(executor, cf.ProcessPoolExecutor):
        # The caller's pool, kept alive by us only until it breaks; our replacements are ours.
        ex = _RespawningPool(executor, own=False)
        try:
            yield ex
        finally:
            ex.shutdown(wait=True)
    elif isinstance(executor, str):
        if executor != "serial":
            raise ValueError(f"executor = {executor!r}: pass 'serial', None (a process pool), a "
                             "concurrent.futures.Executor or a distributed.Client")
        yield _SerialExecutor()
    elif _is_dask_client(executor):
        yield executor.get_executor(pure=False)
    elif hasattr(executor, "submit"):
        yield executor
    else:
        raise ValueError(f"executor = {executor!r} has no submit(); pass a concurrent.futures.Executor "
                         "or a distributed.Client")


def worker_count(ex) -> Optional[int]:
    """How many runs the executor ``ex`` (from :func:`open_executor`) runs at once: a process
    pool's workers, 1 for 'serial'; None where it is not known (a Dask cluster grows and
    shrinks)."""
    if isinstance(ex, _SerialExecutor):
        return 1
    n = getattr(ex, "_max_workers", None)
    return n if isinstance(n, int) and n >= 1 else None


def stroke_plan(specs: Sequence[RunSpec], workers: Optional[int]):
    """Which of ``specs`` (one per relaxed pellet) to submit first, and with which ``ladder``:
    where the piston strokes (``RunSpec.stroke_key``) are at least as many as the ``workers``,
    each stroke's highest pressure goes first with the lower ones as its ladder, and their
    runs wait for it (loading their pellets from the relaxed_dir it fills); with fewer
    strokes, or ``workers`` unknown, every spec goes first on its own (the workers would
    otherwise wait for the stroke). Returns ([(index, ladder)], {index of a stroke's top:
    indices of its lower pressures})."""
    strokes: Dict[str, List[int]] = {}
    for i, spec in enumerate(specs):
        strokes.setdefault(spec.stroke_key, []).append(i)
    ladder = workers is not None and len(strokes) >= workers
    first, after = [], {}
    for idx in strokes.values():
        idx.sort(key=lambda i: specs[i].sigma_z)
        if ladder and len(idx) > 1:
            after[idx[-1]] = idx[:-1]
            first.append((idx[-1], tuple(specs[i].sigma_z for i in idx[:-1])))
        else:
            first.extend((i, ()) for i in idx)
    return first, after


def with_relaxed_dir(runner, relaxed_dir):
    """``runner`` as it is run: :func:`pelletdem.worker.run_point` bound to ``relaxed_dir``
    (a directory, created here, for relaxed-pellet checkpoints; a picklable partial) when
    both are given; any other runner, or ``relaxed_dir`` None, unchanged."""
    if relaxed_dir is None or runner is not run_point:
        return runner
    import functools

    os.makedirs(os.fspath(relaxed_dir), exist_ok=True)
    return functools.partial(run_point, relaxed_dir=os.path.abspath(os.fspath(relaxed_dir)))


class Evaluator:
    """Submits runs, serves cached ones, never runs a key twice, writes the cache.

    ``cache``: the :class:`pelletdem.run_cache.RunCache` records are read from and written
    to; ``executor``: where runs go (:func:`open_executor`); ``runner``: the function run per
    :class:`pelletdem.runs.RunSpec` (:func:`with_relaxed_dir`); ``relaxed_shared``: the runner
    keeps its relaxed pellets where every worker finds them (a ``relaxed_dir``), so the runs of
    one pellet wait for its first (:meth:`run_all`). Counts are in :meth:`stats`.

    A run whose future raises (its worker process died: BrokenProcessPool; or the runner
    raised) is retried once, alone in a fresh worker when the executor is a process pool; if
    the retry fails too the point gets a failed record (``ok`` False, ``error`` with both
    errors, ``worker_failure`` True) that is not cached, so a resumed scan tries it again, and
    the rest of the scan goes on. KeyboardInterrupt and SystemExit are not retried."""

    RETRIES = 1

    def __init__(self, cache: RunCache, executor, runner: Callable[[RunSpec], dict], relaxed_shared: bool = False):
        self.cache, self.executor, self.runner = cache, executor, runner
        self.relaxed_shared = bool(relaxed_shared)
        self._lock = threading.Lock()
        self._inflight: Dict[str, cf.Future] = {}
        self.n_run = 0          # runs executed now
        self.n_cached = 0       # runs served from the cache
        self.n_relaxations = 0  # relaxations done by the runs executed now
        self.sim_time_s = 0.0
        self.n_retried = 0      # runs submitted again after their first attempt failed
        self.failures: List[dict] = []  # points that failed every attempt: key, error, attempts

    def submit(self, spec: RunSpec, rerun: bool = False) -> cf.Future:
        """The run's record as a future: from the cache, or run now (``rerun``: run even when
        cached, e.g. to recreate a relaxed pellet whose checkpoint is gone; deterministic, so
        the record comes out the same)."""
        key = spec.key
        with self._lock:
            if key in self._inflight:
                return self._inflight[key]
            rec = None if rerun else self.cache.get(key)
            out = cf.Future()
            if rec is not None:
                self.n_cached += 1
                rec = dict(rec, cached=True)
                out.set_result(rec)
                self._inflight[key] = out
                return out
            self._inflight[key] = out
            self.n_run += 1
        try:
            fut = self.executor.submit(self.runner, spec)
        except BaseException as e:
            with self._lock:
                self._inflight.pop(key, None)
                self.n_run -= 1
            out.set_exception(e)
            return out
        fut.add_done_callback(lambda f: self._done(spec, f, out, []))
        return out

    def _done(self, spec: RunSpec, fut, out: cf.Future, errors: List[str]) -> None:
        key = spec.key
        try:
            rec = fut.result()
        except BaseException as e:  # noqa: BLE001
            retry = isinstance(e, Exception) and not isinstance(e, cf.CancelledError) and not out.cancelled()
            if retry:
                errors = errors + [f"{type(e).__name__}: {e}"]
                if len(errors) <= self.RETRIES:
                    self._retry(spec, out, errors)
                    return
                rec = self._failed_record(spec, errors)
                with self._lock:
                    self._inflight.pop(key, None)
                    self.failures.append({"key": key, "error": rec["error"], "attempts": len(errors)})
                _set(out, result=rec)
                return
            with self._lock:
                self._inflight.pop(key, None)
            _set(out, error=e)
            return
        try:
            self.cache.put(rec)
        except Exception as e:  # noqa: BLE001 (a full disk must not lose the result)
            warnings.warn(f"could not write cache record {key}: {e}", stacklevel=2)
        with self._lock:
            self.n_relaxations += int(rec.get("relaxations", 0 if rec.get("relaxed_reused") else 1))
            self.sim_time_s += float(rec.get("wall_time_s", 0.0))
        _set(out, result=dict(rec, cached=False, attempts=len(errors) + 1))

    def _retry(self, spec: RunSpec, out: cf.Future, errors: List[str]) -> None:
        with self._lock:
            self.n_retried += 1
        try:
            isolated = getattr(self.executor, "submit_isolated", None)
            fut = isolated(self.runner, spec) if isolated else self.executor.submit(self.runner, spec)
        except Exception as e:  # noqa: BLE001 (an executor that refuses counts as a failed attempt)
            fut = cf.Future()
            fut.set_exception(e)
        fut.add_done_callback(lambda f: self._done(spec, f, out, errors))

    @staticmethod
    def _failed_record(spec: RunSpec, errors: List[str]) -> dict:
        return {"key": spec.key, "relax_key": spec.relax_key, "spec": canonical(spec.payload()), "ok": False,
                "error": f"failed {len(errors)} times, " + "; then ".join(errors),
                "outputs": {}, "curve": {}, "compaction_curve": {}, "relaxed_reused": True,
                "relaxed_from": "", "wall_time_s": 0.0, "worker": "", "cached": False,
                "attempts": len(errors), "worker_failure": True}

    def run_all(self, specs: Sequence[RunSpec]) -> List[dict]:
        """Records of all specs (submitted grouped by relax key), in the order given.

        With ``relaxed_shared`` (the workers reach one ``relaxed_dir``) only the first run of
        each relaxed pellet is submitted at once, and the rest of its group once that run is
        done: two idle workers handed two runs of one pellet would each compact it, and a
        design whose points share relaxed pellets would save nothing. Pellets that differ only
        in sigma_z come from one piston stroke (``RunSpec.ladder``: the highest pressure's run
        relaxes the lower ones' pellets on the way, and their runs wait for it) where the
        strokes are at least as many as the workers; with fewer, the workers would wait."""
        order = sorted(range(len(specs)), key=lambda i: (specs[i].relax_key, i))
        if not self.relaxed_shared:
            futs = {i: self.submit(specs[i]) for i in order}
            return self._gather(futs, len(specs))
        groups: Dict[str, List[int]] = {}
        for i in order:
            groups.setdefault(specs[i].relax_key, []).append(i)
        keys = list(groups)
        plan, waits = stroke_plan([specs[groups[k][0]] for k in keys], worker_count(self.executor))
        first = [(keys[j], lower) for j, lower in plan]  # (relax key, ladder) to submit now
        after = {keys[j]: [keys[i] for i in low] for j, low in waits.items()}  # stroke top -> lower keys
        # every submission from this thread: an executor's own callback thread may not submit
        ready: "queue.Queue[str]" = queue.Queue()
        futs: Dict[int, cf.Future] = {}

        def start(key: str, lower=()) -> None:
            i = groups[key][0]
            futs[i] = self.submit(dataclasses.replace(specs[i], ladder=lower) if lower else specs[i])
            futs[i].add_done_callback(lambda _, key=key: ready.put(key))
        try:
            for key, lower in first:
                start(key, lower)
            for _ in range(len(groups)):
                key = ready.get()
                for i in groups[key][1:]:  # the rest of a group, once its pellet is relaxed
                    futs[i] = self.submit(specs[i])
                for k in after.pop(key, []):  # a stroke's lower pressures, once it is done
                    start(k)
        except BaseException:
            for f in futs.values():
                f.cancel()
            raise
        return self._gather(futs, len(specs))

    @staticmethod
    def _gather(futs: Dict[int, cf.Future], n: int) -> List[dict]:
        try:
            return [futs[i].result() for i in range(n)]
        except BaseException:
            for f in futs.values():
                f.cancel()
            raise

    def stats(self) -> dict:
        """Counts so far: runs executed (``n_simulations``), served from the cache
        (``n_cached``), relaxations done (``n_relaxations``), their wall time
        (``simulation_time_s``, s), retries (``n_retried``) and points that failed every
        attempt (``n_failed``, ``failures``)."""
        return {"n_simulations": self.n_run, "n_cached": self.n_cached,
                "n_relaxations": self.n_relaxations, "simulation_time_s": self.sim_time_s,
                "n_retried": self.n_retried, "n_failed": len(self.failures),
                "failures": list(self.failures)}


def _set(fut: cf.Future, result=None, error=None) -> None:
    # A future cancelled by run_all (another point raised) takes no result.
    try:
        if error is not None:
            fut.set_exception(error)
        else:
            fut.set_result(result)
    except cf.InvalidStateError:
        pass

