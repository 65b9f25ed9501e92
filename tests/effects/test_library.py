"""The library of candidate effects as a whole: each effect is its three files (a C++ header
in cpp/include/pelletdem/effects/, a module in pelletdem.effects, a test here), its parameter
is a row of its law's table, and off it is the paper's law."""
from __future__ import annotations

from pathlib import Path

import pytest

import pelletdem as pd
from pelletdem.effects import EFFECTS

ROOT = Path(__file__).resolve().parents[2]
HEADERS = sorted(p.stem for p in (ROOT / "cpp" / "include" / "pelletdem" / "effects").glob("*.hpp"))


def test_every_header_has_its_declaration_and_its_test():
    assert HEADERS, "no effect headers found"
    assert sorted(EFFECTS) == HEADERS
    for name in HEADERS:
        assert (ROOT / "python" / "pelletdem" / "effects" / f"{name}.py").is_file(), name
        assert (ROOT / "tests" / "effects" / f"test_{name}.py").is_file(), name


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_an_effect_is_off_by_default_and_its_probe_is_allowed(name):
    e = EFFECTS[name]
    law = pd.ContactLaw if e.param.startswith("contact.") else pd.BondLaw
    field = e.param.split(".", 1)[1]
    assert getattr(law(), field) == e.off
    for value in (e.lo, e.probe, e.hi):  # the whole fit range passes the law's checks
        law(**{field: value, **{k.split(".", 1)[1]: v for k, v in e.fixed.items()}}).to_core()


@pytest.mark.parametrize("field,value", [
    ("weibull_modulus", 0.1), ("weibull_modulus", float("nan")), ("strength_seed", -1.0),
    ("strength_seed", 0.5), ("softening", -1.0), ("overlap_radius_gain", -0.1),
    ("moisture_coefficient", 2.0)])
def test_bad_bond_effect_parameters_name_themselves(field, value):
    with pytest.raises(ValueError, match=field):
        pd.BondLaw(**{field: value}).to_core()


@pytest.mark.parametrize("field,value", [("unloading_growth", -1.0), ("plate_yield_stress", -1.0),
                                         ("unloading_growth", float("inf")), ("hardening", -1.0),
                                         ("hardening_exponent", 9.0), ("moisture_yield", 2.0),
                                         ("moisture_content", 150.0), ("moisture_reference", -1.0),
                                         ("wood_density_yield", 20.0), ("wood_density", 10.0),
                                         ("wood_density_reference", float("nan")), ("densified_yield", 0.5),
                                         ("interlocking_friction", 0.5)])
def test_bad_contact_effect_parameters_name_themselves(field, value):
    with pytest.raises(ValueError, match=field):
        pd.ContactLaw(**{field: value}).to_core()


def test_an_effect_must_name_a_row_with_its_unit_and_default():
    from pelletdem.effects import Effect

    with pytest.raises(ValueError, match="no row"):
        Effect("x", "contact.no_such_field", "-", 0.1, 1.0, 0.5, True, 0.0, "diametral", "", "")
    with pytest.raises(ValueError, match="unit"):
        Effect("x", "contact.plate_yield_stress", "-", 0.1, 1.0, 0.5, True, 0.0, "diametral", "", "")
    with pytest.raises(ValueError, match="defaults"):
        Effect("x", "bond.softening", "-", 0.1, 1.0, 0.5, True, 1.0, "diametral", "", "")


def test_effects_that_cannot_be_on_together_say_why():
    from pelletdem.effects import clash

    both = clash([EFFECTS["unloading_growth"], EFFECTS["saturating_unloading"]])
    assert "unloading stiffness" in both
    assert clash([EFFECTS["unloading_growth"], EFFECTS["hardening"], EFFECTS["weibull_strength"]]) == ""
    assert clash([]) == ""
