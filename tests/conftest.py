"""Test-session set-up.

OMP_WAIT_POLICY=PASSIVE: idle OpenMP threads sleep instead of spinning. On a machine with more
runnable processes than cores (CI, a shared workstation) spinning threads fight the threads
doing the work, and a two-thread step ran ~50x slower than a one-thread step here. It has to be
set before the engine (and so libgomp) is loaded, hence here; a value set by the user wins.
"""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
