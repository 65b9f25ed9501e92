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
