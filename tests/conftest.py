"""Test-session set-up.

OMP_WAIT_POLICY=PASSIVE: idle OpenMP threads sleep instead of spinning. On a machine with more
runnable processes than cores (CI, a shared workstation) spinning threads fight the threads
doing the work, and a two-thread step ran ~50x slower than a one-thread step here. It has to be
set before the engine (and so libgomp) is loaded, hence here; a value set by the user wins.
"""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("GOMP_SPINCOUNT", "20000")


import pytest  # noqa: E402

# The bond law under which the 'tiny' pellet (400 particles, 3 mm mould) breaks within the
# diametral test. With the paper's Table 5 oak bonds (MC 8 %, 120 MPa: E_b = 120 MPa,
# sigma_c = 36 MPa) the tiny pellet, looser than the paper's, fails only around dL/D = 0.1,
# where the preset's test ends.
# A quarter of both keeps sigma_c / E_b = 0.3 (the same bond strain at failure) and gives a
# clear peak near dL/D = 0.1 with a fall of about a third after it by dL/D = 0.15.
TINY_BOND = {"youngs_modulus": 30e6, "sigma_c": 9e6, "tau_c": 9e6}
TINY_MAX_DLD = 0.15
TINY_SIGMA_Z = 120e6  # Pa


@pytest.fixture(scope="session")
def tiny_life():
    """One whole pellet life on the 'tiny' preset (seed 0, one thread), run once per test
    session and shared read-only: fill -> compact (120 MPa) -> unload -> demould -> relax ->
    bond (TINY_BOND) -> diametral (to dL/D = TINY_MAX_DLD). Returns a namespace with the
    Pellet (`pellet`, its world after the test), the Result (`result`), a copy of the
    relaxed pellet (`relaxed`: clone its world again before using it) and the inputs."""
    import time
    from types import SimpleNamespace

    from pelletdem import pipeline
    from pelletdem.calibrate import clone_pellet
    from pelletdem.engine import BondLaw

    law = BondLaw(**TINY_BOND)
    t0 = time.perf_counter()
    pellet, res = pipeline.relaxed_pellet("tiny", sigma_z=TINY_SIGMA_Z, seed=0, threads=1, progress=False)
    relaxed = clone_pellet(pellet)
    pipeline.break_pellet(pellet, law, res, max_dLD=TINY_MAX_DLD, progress=False)
    return SimpleNamespace(pellet=pellet, result=res, bond_law=law, max_dLD=TINY_MAX_DLD,
                           sigma_z=TINY_SIGMA_Z, wall_time_s=time.perf_counter() - t0,
                           relaxed=relaxed)
