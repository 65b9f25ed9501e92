"""The library of candidate effects the discrepancy loop (:mod:`pelletdem.loop`) can add.

Each effect is an optional part of the C++ contact or bond law (off by default, so the
baseline is the paper's model) with one fitted parameter, and comes with the residual
signature it leaves when the data carry it and the model does not. The loop measures each
signature numerically (one simulation per condition at a probe strength) and ranks the
candidates by how much of the residual it explains; the text is what a person reads.

An effect is three files (docs/adding-an-effect.md): its C++ header in
``cpp/include/pelletdem/effects/`` (parameter rows and hooks), a module here that declares it
(``EFFECT = Effect(...)``), and its test in ``tests/effects/``. Every module of this package
that defines ``EFFECT`` is in :data:`EFFECTS`, in the order of the modules' names.

Parameter names are ``contact.<field>`` (a :class:`~pelletdem.laws.ContactLaw` field) or
``bond.<field>`` (a :class:`~pelletdem.laws.BondLaw` field), so any simulator that knows
those laws can switch the effect on.
"""
from __future__ import annotations

import importlib
import pkgutil
from typing import Dict, Tuple

from .base import Effect, clash

__all__ = ["Effect", "EFFECTS", "effect_names", "clash"]


def _discover() -> Dict[str, Effect]:
    found: Dict[str, Effect] = {}
    for mod in sorted(m.name for m in pkgutil.iter_modules(__path__)):
        effect = getattr(importlib.import_module(f"{__name__}.{mod}"), "EFFECT", None)
        if isinstance(effect, Effect):
            if effect.name in found:
                raise ValueError(f"two effects are called {effect.name!r}")
            found[effect.name] = effect
    return found


#: The shipped candidate effects by name.
EFFECTS: Dict[str, Effect] = _discover()


def effect_names() -> Tuple[str, ...]:
    """Names of the shipped candidate effects, in library order."""
    return tuple(EFFECTS)
