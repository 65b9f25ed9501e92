"""The paper's measurements as a discrepancy-loop problem (``pelletdem loop --data paper``).

The data are Table 3's sigma_f and dL_f/D and Table 2's pellet bulk density of the chosen
materials' variants (two moisture contents, two pressures each). The bonds, E_b and sigma_c,
are fitted per material and shared by its four variants: the paper fits them per variant
(Table 5), which leaves nothing over for a held-out variant to check and lets the bonds absorb
every trend with pressure and moisture, the trends the loop is meant to trace. Other base
parameters (the contact's k1 or p_y, say) may be fitted too, shared by every variant. Which
variants are held out is a selector on their conditions, by default MC 20 % at 60 MPa. Each
material's particles have its intact wood's bulk density (Table 2's BD_w; Table 4's 680
kg/m^3 is oak's): the model's pellet density is its solid fraction times that.
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Iterable, Optional, Sequence, Tuple

from .loop_data import Condition, Dataset

__all__ = ["PER_MATERIAL", "DEFAULT_HELD_OUT", "PAPER_OVERLAP_GUARD", "held_out_selector", "shared_bounds",
           "paper_problem", "particle_densities", "paper_preset"]

#: Base parameters fitted per material, with their bounds (SI). The tiny pellet's bonds fit above
#: Table 5's (oak E_b 53-120 MPa; birch and pine 9-50 MPa lie below 1e8): a fit at a bound widens the box.
PER_MATERIAL: Dict[str, Tuple[float, float]] = {"E_b": (1e8, 1e10), "sigma_c": (5e6, 5e8)}
#: The engine's guard on overlap / smaller radius for the paper's pellets (the presets': 1.5).
#: The paper's relaxed pellets have a nominal solid fraction of 1.62 (BD_p / BD_w, Fig. 10),
#: which the model reaches only with k1 near 3-4e4 N/m, where at 120 MPa small particles sink
#: past 1.5 radii into their neighbours while the run stays sound (the relaxed density of the
#: packings that pass 1.5 is within 1 % of those that do not); 2 is a small sphere wholly
#: inside a large one, where the contact's geometry ends.
PAPER_OVERLAP_GUARD = 2.0
#: The variants held out when none are named: the wettest, least compacted ones.
DEFAULT_HELD_OUT = "mc=20,sigma_z=60"

_KEYS = {"mc": "moisture content, %", "sigma_z": "compaction pressure, MPa", "material": "material name"}


def held_out_selector(text: str) -> Callable[[Condition], bool]:
    """A test of a condition from ``"key=value[,key=value...]"``: true where every key matches
    (keys ``mc`` in %, ``sigma_z`` in MPa, ``material``); ValueError naming what is wrong."""
    wanted: Dict[str, object] = {}
    for part in str(text).split(","):
        key, eq, value = part.strip().partition("=")
        key, value = key.strip(), value.strip()
        if not eq or not value or key not in _KEYS:
            raise ValueError(f"--held-out {text!r}: expected key=value[,key=value], keys "
                             + ", ".join(f"{k} ({m})" for k, m in _KEYS.items()))
        if key in wanted:
            raise ValueError(f"--held-out {text!r}: {key} given twice")
        if key == "material":
            wanted[key] = value
            continue
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"--held-out {text!r}: {key} = {value!r} is not a number") from None
        if not math.isfinite(number):
            raise ValueError(f"--held-out {text!r}: {key} = {value!r} must be finite")
        wanted[key] = number

    def test(c: Condition) -> bool:
        return (wanted.get("mc", c.mc) == c.mc and wanted.get("material", c.material) == c.material
                and wanted.get("sigma_z", c.sigma_z / 1e6) == c.sigma_z / 1e6)

    return test


def shared_bounds(items: Iterable[str]) -> Dict[str, Tuple[float, float]]:
    """{name: (lo, hi)} (SI) from ``"NAME=LO:HI"`` strings: base parameters fitted once for
    every variant. NAME is one of :data:`pelletdem.runs.PARAMETERS` other than the per-material
    ones and sigma_z (k1, p_y, r_b, tau_c; positive bounds), or a law row ``contact.X`` /
    ``bond.X``, whose bounds are checked against its table (a signed row may take negative
    ones: it is then fitted on a linear axis)."""
    from .law_settings import parse_setting
    from .runs import PARAMETERS

    allowed = sorted(set(PARAMETERS) - set(PER_MATERIAL) - {"sigma_z"})
    out: Dict[str, Tuple[float, float]] = {}
    for item in items or ():
        name, eq, rng = str(item).partition("=")
        name = name.strip()
        lo_text, colon, hi_text = rng.partition(":")
        if not eq or not colon:
            raise ValueError(f"--fit {item!r}: expected NAME=LO:HI (SI units)")
        if name in PER_MATERIAL:
            raise ValueError(f"--fit {item!r}: {name} is fitted per material already")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            raise ValueError(f"--fit {item!r}: LO and HI must be numbers") from None
        law_row = name.startswith("contact.") or name.startswith("bond.")
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"--fit {item!r}: need LO < HI, finite")
        if law_row:
            parse_setting(name, lo)  # the row exists and takes both ends (a signed row: either sign)
            parse_setting(name, hi)
        elif name not in allowed:
            raise ValueError(f"--fit {item!r}: allowed {', '.join(allowed)} or contact.X / bond.X")
        elif lo <= 0:
            raise ValueError(f"--fit {item!r}: {name} needs 0 < LO < HI")
        if name in out:
            raise ValueError(f"--fit {name} given twice")
        out[name] = (lo, hi)
    return out


def paper_problem(materials: Sequence[str], held_out: str = DEFAULT_HELD_OUT,
                  shared: Optional[Iterable[str]] = None) -> Tuple[Dataset, Tuple[Condition, ...], Dict]:
    """(dataset, held-out conditions, bounds) of the paper's ``materials``: ``held_out`` a
    selector (:func:`held_out_selector`), ``shared`` extra base parameters
    (:func:`shared_bounds`). ValueError when the selector holds out nothing or everything."""
    test = held_out_selector(held_out)
    extra = shared_bounds(shared or ())
    data = Dataset.from_paper(materials=list(materials))
    held = tuple(c for c in data.conditions if test(c))
    if not held:
        raise ValueError(f"--held-out {held_out!r} selects none of "
                         + ", ".join(c.label for c in data.conditions))
    if len(held) == len(data.conditions):
        raise ValueError(f"--held-out {held_out!r} selects every variant: none would be fitted")
    bounds = {f"{p}[{m}]": b for m in materials for p, b in PER_MATERIAL.items()}
    bounds.update(extra)
    return data, held, bounds


def particle_densities(materials: Sequence[str]) -> Dict[str, float]:
    """{material: its particles' density, kg/m^3}: Table 2's bulk density of the intact wood
    (measured at MC 8 % only, used at both moisture contents). A sawdust particle is a piece of
    wood with the wood's own pores; Table 1's pycnometric densities are of the cell wall."""
    from .paper_tables import variants

    out = {v.material: float(v.bd_wood) for v in variants() if v.material in set(materials)}
    missing = sorted(set(materials) - set(out))
    if missing:
        raise ValueError(f"materials {missing}: allowed {sorted({v.material for v in variants()})}")
    return out


def paper_preset(preset):
    """The preset (name or Preset) the paper's variants run with: ``preset`` with the
    overlap guard at :data:`PAPER_OVERLAP_GUARD`."""
    from .runs import as_preset

    return as_preset(preset).with_(max_overlap_ratio=PAPER_OVERLAP_GUARD)
