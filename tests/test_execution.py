"""Worker pools (pelletdem.execution): a script that would start worker processes from its top
level, outside ``if __name__ == "__main__":``, is told so before any worker starts; the same
script with the guard runs."""
from __future__ import annotations

import re
import subprocess
import sys
import textwrap

POOL = """
from pelletdem.execution import open_executor

def square(x):
    return x * x
"""


def _run(tmp_path, body: str) -> subprocess.CompletedProcess:
    script = tmp_path / "study.py"
    script.write_text(textwrap.dedent(POOL) + textwrap.dedent(body))
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)


def test_an_unguarded_script_is_told_which_line_to_guard(tmp_path):
    r = _run(tmp_path, """
        with open_executor(None, 1) as ex:
            print(ex.submit(square, 3).result())
    """)
    assert r.returncode != 0 and 'if __name__ == "__main__":' in r.stderr
    line = int(re.search(r"study\.py, line (\d+): worker processes", r.stderr).group(1))
    assert (tmp_path / "study.py").read_text().splitlines()[line - 1].startswith("with open_executor")
    assert "9" not in r.stdout


def test_a_guarded_script_runs_its_workers(tmp_path):
    r = _run(tmp_path, """
        def main():
            with open_executor(None, 1) as ex:
                print(ex.submit(square, 3).result())

        if __name__ == "__main__":
            main()
    """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "9"


def test_calls_from_a_function_or_a_notebook_are_not_checked():
    from pelletdem.execution import unguarded_main_line

    assert unguarded_main_line() is None  # pytest's __main__ runs no test at its top level


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie nobody reaps counts as gone)."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            state = next(line for line in fh if line.startswith("State:"))
    except (FileNotFoundError, StopIteration):
        return False
    return "Z" not in state.split()[1]


def test_workers_end_when_their_driver_is_killed(tmp_path):
    # SIGKILL on the driver alone (as `pkill` does) runs no shutdown: the workers must notice
    import os
    import signal
    import time

    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent("""
        import os, time
        from pelletdem.execution import open_executor

        if __name__ == "__main__":
            with open_executor(None, 1) as ex:
                print(ex.submit(os.getpid).result(), flush=True)
                time.sleep(120)
    """))
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        worker = int(p.stdout.readline())
        assert _alive(worker)
        os.kill(p.pid, signal.SIGKILL)
        p.wait(10)
        t0 = time.monotonic()
        while _alive(worker) and time.monotonic() - t0 < 15:
            time.sleep(0.2)
        assert not _alive(worker), "the worker outlived its driver"
    finally:
        p.kill()


class _Spec:
    """A run with only what the Evaluator reads: its key and its relaxed pellet's key."""

    def __init__(self, key: str, relax_key: str):
        self.key, self.relax_key = key, relax_key


def _timed_runner(log, lock, together=None):
    """A run that takes 20 ms and logs (relax key, start, end); with ``together`` (a list),
    the first two runs wait for each other (up to 5 s) and log there whether they met: two
    runs at once, however loaded the machine."""
    import threading
    import time

    meet = threading.Barrier(2)
    count = []

    def run(spec):
        with lock:
            count.append(spec.key)
            first_two = len(count) <= 2
        if together is not None and first_two:
            try:
                meet.wait(timeout=5.0)
                together.append(True)
            except threading.BrokenBarrierError:
                together.append(False)
        t0 = time.perf_counter()
        time.sleep(0.02)
        with lock:
            log.append((spec.relax_key, t0, time.perf_counter()))
        return {"key": spec.key, "ok": True, "relaxed_reused": True, "wall_time_s": 0.0}
    return run


def test_runs_of_one_relaxed_pellet_wait_for_the_first_where_workers_share_pellets():
    import concurrent.futures as cf
    import threading

    from pelletdem.execution import Evaluator
    from pelletdem.run_cache import RunCache

    specs = [_Spec(f"k{g}{i}", f"r{g}") for g in range(3) for i in range(4)]
    log, lock, together = [], threading.Lock(), []
    with cf.ThreadPoolExecutor(2) as ex:
        ev = Evaluator(RunCache(), ex, _timed_runner(log, lock, together), relaxed_shared=True)
        recs = ev.run_all(specs[::-1])
    assert [r["key"] for r in recs] == [s.key for s in specs[::-1]]  # the order given
    for g in range(3):
        runs = sorted((t0, t1) for r, t0, t1 in log if r == f"r{g}")
        assert len(runs) == 4
        assert all(t0 >= runs[0][1] for t0, _ in runs[1:])  # none began before the first ended
    assert together == [True, True]  # two pellets' first runs went out at once: both workers used


def test_runs_of_one_relaxed_pellet_go_out_together_where_workers_do_not_share_pellets():
    import concurrent.futures as cf
    import threading

    from pelletdem.execution import Evaluator
    from pelletdem.run_cache import RunCache

    specs = [_Spec(f"k{i}", "r0") for i in range(4)]
    log, lock, together = [], threading.Lock(), []
    with cf.ThreadPoolExecutor(2) as ex:
        Evaluator(RunCache(), ex, _timed_runner(log, lock, together)).run_all(specs)
    assert together == [True, True] and len(log) == 4  # two runs of the one pellet at once
