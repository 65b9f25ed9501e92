"""The Python World is the engine's API as users see it: every method and property of the
compiled world is defined on it with a docstring (none is forwarded unseen), and an attribute
it does not have is an AttributeError, not a silent pass-through."""
from __future__ import annotations

import inspect

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import _core

# Engine methods the Python World reaches another way: set_state through from_state and
# restore_state (which rebuild the Python side too).
HIDDEN = {"set_state"}


def _public(names):
    return {n for n in names if not n.startswith("_")}


def test_every_engine_method_is_defined_on_the_python_world():
    core = _public(dir(_core.World)) - HIDDEN
    missing = sorted(n for n in core if n not in vars(pd.World))
    assert missing == [], "defined in _core.World, not on pelletdem.World"


@pytest.mark.parametrize("name", sorted(_public(vars(pd.World))))
def test_every_public_member_has_a_docstring(name):
    member = inspect.getattr_static(pd.World, name)
    doc = member.__doc__ if not isinstance(member, property) else member.fget.__doc__
    assert doc and doc.strip(), f"World.{name} has no docstring"


def test_an_unknown_attribute_is_an_error():
    w = pd.World()
    with pytest.raises(AttributeError):
        w.no_such_method()


def test_settable_properties_reach_the_engine():
    w = pd.World()
    w.add_particles(np.zeros((1, 3)), np.array([2e-4]))
    w.dt = 1e-6
    w.gravity = (0.0, 0.0, -1.0)
    w.vector_kernels = False
    assert w.dt == 1e-6 and w._core.dt == 1e-6
    assert w.gravity == (0.0, 0.0, -1.0)
    assert w._core.vector_kernels is False
