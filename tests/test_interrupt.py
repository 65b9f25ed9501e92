"""Ctrl-C and other Python threads during a long engine run (World.run / run_until).

The engine runs in chunks of about 0.1 s of wall time with the GIL released and checks for
signals between chunks. A SIGINT (from the terminal, `os.kill`, or `_thread.interrupt_main`)
therefore raises KeyboardInterrupt within a fraction of a second, the world is left exactly
at a step boundary (it equals a world run that many steps without interruption, bit for bit),
it can run on, and a checkpoint saved after the interrupt restores it. While a chunk runs,
other Python threads run too.
"""
import _thread
import os
import signal
import threading
import time

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import checkpoint

LONG = 10**9  # steps: hours of work, so only the interrupt can end the run


def settling_bed(seed=1):
    """400 polydisperse spheres falling into a 3 mm mould under raised gravity: contacts from
    the first few hundred steps, adhesion, friction (the paper's default law)."""
    r = pd.truncated_normal_radii(400, seed=seed)
    x, r = pd.random_pack_cylinder(r, radius=1.5e-3, z_lo=0.0, z_hi=0.012, seed=seed + 1)
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 0.015)), gravity=(0, 0, -9.81e4))
    w.add_particles(x, r)
    w.add_plane("floor", (0, 0, 0), (0, 0, 1))
    w.add_cylinder("mould", (0, 0, 0), 1.5e-3)
    return w


def state(w):
    return np.concatenate([w.positions(), w.velocities(), np.array(w.w), np.array(w.f)], axis=1)


def _interrupt_after(delay, how):
    """Start a thread that interrupts the main thread after `delay` s; returns (thread, box)
    where box['sent'] is the perf_counter time the interrupt was sent."""
    box = {}

    def fire():
        box["sent"] = time.perf_counter()
        if how == "kill":
            os.kill(os.getpid(), signal.SIGINT)
        else:
            _thread.interrupt_main()  # a simulated SIGINT (what IDEs and Jupyter send)

    t = threading.Timer(delay, fire)
    t.daemon = True
    return t, box


@pytest.fixture
def default_sigint():
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.parametrize("how", ["kill", "interrupt_main"])
def test_sigint_stops_a_long_run_within_a_second_and_leaves_a_consistent_world(how, default_sigint, tmp_path):
    w = settling_bed()
    w.run(200)  # forces, contacts and a neighbour list exist before the long run
    timer, box = _interrupt_after(0.5, how)
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        w.run_until(max_steps=LONG)
    caught = time.perf_counter()
    timer.join()
    latency = caught - box["sent"]
    assert latency < 1.0, f"the run went on {latency:.2f} s after the interrupt"
    steps = w.step_count
    assert 200 < steps < LONG

    # Consistent: exactly the world that ran `steps` steps without an interrupt.
    ref = settling_bed()
    ref.run(steps)
    assert ref.step_count == steps and ref.time == w.time
    assert np.array_equal(state(w), state(ref))

    # Resumable: a checkpoint taken now restores a world that goes on identically, and the
    # interrupted world itself can run on.
    path = checkpoint.save_world(w, tmp_path / "after_interrupt.h5")
    back = checkpoint.load_world(path)
    for x in (w, ref, back):
        x.run(300)
    assert np.array_equal(state(w), state(ref))
    assert np.array_equal(state(back), state(ref))
    assert w.contact_count == back.contact_count > 0


def test_interrupt_during_a_progress_callback_is_also_clean(default_sigint):
    """A KeyboardInterrupt raised by Python code between chunks (here the progress callback)
    leaves the world at a step boundary too."""
    w = settling_bed()
    calls = []

    def progress(done):
        calls.append(done)
        if len(calls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        w.run_until(max_steps=LONG, progress=progress)
    assert w.step_count == calls[-1]
    ref = settling_bed()
    ref.run(calls[-1])
    assert np.array_equal(state(w), state(ref))


def test_other_python_threads_run_while_the_engine_steps():
    """The GIL is released inside a chunk: a Python thread doing pure-Python work keeps
    running during the chunks, not only between them."""
    w = settling_bed()
    w.run(200)
    # about 0.8 s of stepping whatever the machine's speed (20,000 steps took 0.28 s on one)
    t_cal = time.perf_counter()
    w.run(2000)
    steps = max(20000, int(0.8 * 2000 / (time.perf_counter() - t_cal)))
    ticks, stop = [], threading.Event()

    def busy():
        while not stop.is_set():
            ticks.append(time.perf_counter())  # needs the GIL for every iteration
            x = 0
            for k in range(200):
                x += k

    bounds = []
    t = threading.Thread(target=busy, daemon=True)
    t.start()
    t0 = time.perf_counter()
    w.run_until(max_steps=LONG, time=w.time + steps * w.dt,
                progress=lambda done: bounds.append(time.perf_counter()))
    run_s = time.perf_counter() - t0
    stop.set()
    t.join()
    # Ticks strictly inside chunks (10 ms clear of each chunk's ends, where the GIL is held).
    edges = [t0] + bounds
    ticks = np.asarray(ticks)
    inside = sum(int(np.sum((ticks > a + 0.01) & (ticks < b - 0.01))) for a, b in zip(edges[:-1], edges[1:]))
    long_chunks = sum(b - a > 0.05 for a, b in zip(edges[:-1], edges[1:]))
    assert run_s > 0.3 and long_chunks >= 2, (run_s, long_chunks)
    assert inside > 100, f"only {inside} Python ticks inside {long_chunks} chunks of {run_s:.2f} s"
