"""Worker pools (pelletdem.execution): a script that would start worker processes from its top
level, outside ``if __name__ == "__main__":``, is told so before any worker starts; the same
script with the guard runs."""
from __future__ import annotations

import dataclasses
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


@dataclasses.dataclass(frozen=True)
class _Spec:
    """A run with only what the Evaluator reads: its key, its relaxed pellet's key, the key of
    the piston stroke that pellet comes from (its own unless given), its pressure (Pa) and
    the lower pressures it is asked to relax on the way."""

    key: str
    relax_key: str
    stroke: str = ""
    sigma_z: float = 120e6
    ladder: tuple = ()

    @property
    def stroke_key(self) -> str:
        return self.stroke or self.relax_key


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


def _stroke_runs(workers: int):
    """Two strokes (packings), each with a 60 and a 120 MPa pellet, on ``workers`` threads:
    {(stroke, sigma_z): (ladder, start, end)}."""
    import concurrent.futures as cf
    import threading
    import time

    from pelletdem.execution import Evaluator
    from pelletdem.run_cache import RunCache

    specs = [_Spec(f"k{s}{sz:g}", f"r{s}{sz:g}", f"s{s}", sz) for s in range(2) for sz in (60e6, 120e6)]
    log, lock = {}, threading.Lock()

    def run(spec):
        t0 = time.perf_counter()
        time.sleep(0.3)
        with lock:
            log[(spec.stroke, spec.sigma_z)] = (spec.ladder, t0, time.perf_counter())
        return {"key": spec.key, "ok": True, "relaxed_reused": False, "wall_time_s": 0.0}

    with cf.ThreadPoolExecutor(workers) as ex:
        recs = Evaluator(RunCache(), ex, run, relaxed_shared=True).run_all(specs)
    assert [r["key"] for r in recs] == [s.key for s in specs]
    return log


def test_pellets_of_one_stroke_come_from_it_where_strokes_are_as_many_as_the_workers():
    """The 120 MPa run of each stroke goes first with the lower pressure as its ladder; the
    60 MPa run starts once it has ended (and then loads its pellet)."""
    log = _stroke_runs(workers=2)
    for s in ("s0", "s1"):
        (top_ladder, _, top_end), (low_ladder, low_start, _) = log[(s, 120e6)], log[(s, 60e6)]
        assert top_ladder == (60e6,) and low_ladder == ()
        assert low_start >= top_end


def test_pellets_of_one_stroke_compact_side_by_side_where_the_workers_are_more():
    """With more workers than strokes a stroke would keep workers waiting: no ladder, every
    run at once."""
    log = _stroke_runs(workers=4)
    assert all(ladder == () for ladder, _, _ in log.values())
    starts, ends = [t0 for _, t0, _ in log.values()], [t1 for _, _, t1 in log.values()]
    assert max(starts) < min(ends)
