"""A stochastic analytic pellet for the loop's fast tests.

Like the DEM pellet, each packing (seed) gives another pellet: its strength scatters by 5 %,
its deformation at failure by 6 % and each point of its curve a little more, and an effect that
acts during compaction changes the packing (a new draw of that scatter), as a change of a
compaction parameter sends the DEM particles elsewhere. The diametral curve is
S g(x / x_f) with g(t) = t exp(1 - t) up to the peak and exp(-3 (t - 1) / (1 + 2 s)) after it;
S = 1e3 sigma_c (sigma_z / 120 MPa)^(1 + gain), x_f = sigma_c / E_b. Effects, through law-style
names: plate crushing shifts the curve's toe, bond softening slows the fall after the peak,
the overlap radius gain steepens the strength's rise with pressure, unloading growth lowers
the density (compaction stage) and with it the strength (as the fourth power of the density).
``bond.kt_ratio`` != 1 puts a wiggle on the rise: an effect no candidate has.
"""
from __future__ import annotations

import functools
import zlib

import numpy as np

from pelletdem.effects import Effect
from pelletdem.loop import Condition, Prediction

FIT = [Condition(60e6), Condition(120e6)]
HELD = [Condition(90e6)]
TRUTH = {"E_b": 100e6, "sigma_c": 8e6}
START = {"E_b": 70e6, "sigma_c": 10e6}
BOUNDS = {"E_b": (30e6, 300e6), "sigma_c": (3e6, 30e6)}

LIBRARY = {e.name: e for e in (
    Effect("toe", "contact.plate_yield_stress", "Pa", 0.01, 1.0, 0.2, True, 0.0, "diametral",
           "toe shift", "stress too high at small dL/D"),
    Effect("tail", "bond.softening", "-", 0.05, 5.0, 0.5, True, 0.0, "diametral",
           "slow decline after the peak", "post-peak too low"),
    Effect("trend", "bond.overlap_radius_gain", "-", 0.05, 5.0, 0.5, True, 0.0, "diametral",
           "strength rises faster with pressure", "sigma_f trend with sigma_z"),
    Effect("springback", "contact.unloading_growth", "-", 0.1, 50.0, 5.0, True, 0.0, "compaction",
           "more spring-back", "density too high"),
)}

#: The parameters that re-draw the packing (:func:`_packing`).
PACKING = ("contact.unloading_growth",)

#: The packings' scatter: strength, deformation at failure, each curve point, density.
SCATTER = {"S": 0.05, "x_f": 0.06, "point": 0.02, "density": 0.003}


def _packing(seed: int, cond: Condition, growth: float) -> np.random.Generator:
    # a compaction parameter re-draws the packing, as it does in the DEM
    key = f"{seed}|{cond.sigma_z:.6g}|{growth:.17g}".encode()
    return np.random.default_rng(zlib.crc32(key))


def toy(params, c: Condition, seed: int = 0) -> Prediction:
    """One pellet of condition ``c`` from packing ``seed`` under ``params`` (see the module
    docstring)."""
    E, sc = params["E_b"], params["sigma_c"]
    shift = 0.02 * params.get("contact.plate_yield_stress", 0.0)
    tail = params.get("bond.softening", 0.0)
    gain = params.get("bond.overlap_radius_gain", 0.0)
    growth = params.get("contact.unloading_growth", 0.0)
    wiggle = params.get("bond.kt_ratio", 1.0) - 1.0
    rng = _packing(seed, c, growth)
    eS, ex, ed = rng.standard_normal(3)
    loose = 1.0 / (1 + 0.02 * np.log1p(growth))  # the density's fall with spring-back
    x_f0 = sc / E * (1 + SCATTER["x_f"] * ex)
    S = 1e3 * sc * (c.sigma_z / 120e6) * (c.sigma_z / 90e6) ** gain * loose ** 4 * (1 + SCATTER["S"] * eS)
    x = np.linspace(0, 3 * x_f0 + shift, 300)
    t = np.maximum(x - shift, 0) / x_f0
    g = t * np.exp(1 - t)
    post = t > 1
    g[post] = np.exp(-3.0 * (t[post] - 1) / (1 + 2 * tail))
    g = g * (1 + wiggle * np.sin(4 * np.pi * np.minimum(t, 1.0)) * (t < 1))
    # a smooth per-packing jitter along the curve (bonds break in another order)
    phase, amp = rng.uniform(0, 2 * np.pi), SCATTER["point"] * rng.standard_normal()
    y = S * g * (1 + amp * np.sin(2 * np.pi * t + phase))
    k = int(np.argmax(y))
    xc = np.linspace(0.0, 0.6, 60)
    rho = 560.0 * (c.sigma_z / 120e6) ** 0.1 * loose * (1 + SCATTER["density"] * ed)
    sz = c.sigma_z * (xc / 0.6) ** 3
    return Prediction(curve=(x, y), compaction=(xc, sz),
                      scalars={"sigma_f": float(y[k]), "dLf_D": float(x[k]), "bulk_density": float(rho),
                               "peaked": 1.0})


@functools.lru_cache(maxsize=None)
def _example_scales():
    """(stress, dL/D, dh/h0) factors that put the toy on the shipped example's scale: the
    example's sigma_f and dL_f/D at its highest pressure over the toy's there under the
    example's true bond parameters (pelletdem.loop_cli.SYNTHETIC_BOND), and the end of its
    compaction data over the toy's."""
    from pelletdem.loop_cli import SYNTHETIC_BOND
    from pelletdem.loop_manifest import example_manifest, load_manifest

    data = load_manifest(example_manifest()).dataset
    c = max(data.conditions, key=lambda c: c.sigma_z)
    scalars = {o.quantity: o.value for o in data.observations
               if o.condition == c and o.quantity in ("sigma_f", "dLf_D")}
    p = toy({"E_b": SYNTHETIC_BOND["youngs_modulus"], "sigma_c": SYNTHETIC_BOND["sigma_c"]}, c)
    x_end = max(o.x for o in data.observations if o.quantity == "sigma_z")
    return (scalars["sigma_f"] / p.scalars["sigma_f"], scalars["dLf_D"] / p.scalars["dLf_D"],
            x_end / float(np.max(p.compaction[0])))


def example_toy(params, c: Condition, seed: int = 0) -> Prediction:
    """The toy pellet at the scale of the shipped example data (pelletdem/data/loop_example):
    a cheap stand-in for the engine where only the code path matters (notebook 04's fast test)."""
    stress, dl, dh = _example_scales()
    p = toy(params, c, seed)
    (x, y), (xc, sz) = p.curve, p.compaction
    sc = dict(p.scalars, sigma_f=p.scalars["sigma_f"] * stress, dLf_D=p.scalars["dLf_D"] * dl)
    return Prediction(curve=(x * dl, y * stress), compaction=(xc * dh, sz), scalars=sc)
