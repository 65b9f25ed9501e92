"""The paper's measurements as a loop problem (pelletdem.loop_paper and `loop --data paper`):
which variants are held out, which base parameters are fitted, and what is refused."""
from __future__ import annotations

import argparse

import pytest

from pelletdem import loop_cli
from pelletdem.loop_data import Condition
from pelletdem.loop_paper import DEFAULT_HELD_OUT, held_out_selector, paper_problem, shared_bounds


def _args(*extra):
    sub = argparse.ArgumentParser().add_subparsers()
    loop_cli.add_parser(sub)
    return sub.choices["loop"].parse_args(["--out", "unused", *extra])


def test_the_default_holds_out_the_wet_low_pressure_variant_of_each_material():
    data, held, bounds = paper_problem(["oak", "pine"])
    assert sorted(c.label for c in held) == ["oak MC 20% 60 MPa", "pine MC 20% 60 MPa"]
    assert len(data.conditions) == 8
    # the bonds per material; Table 5's (oak 8 %, 120 MPa: E_b 860 MPa, sigma_c 107 MPa) inside
    assert bounds == {"E_b[oak]": (1e8, 1e10), "sigma_c[oak]": (5e6, 5e8),
                      "E_b[pine]": (1e8, 1e10), "sigma_c[pine]": (5e6, 5e8)}
    # densities, strengths and deformations of every variant
    assert {o.quantity for o in data.observations} == {"sigma_f", "dLf_D", "bulk_density"}


@pytest.mark.parametrize("sel,labels", [
    ("sigma_z=60", ["oak MC 20% 60 MPa", "oak MC 8% 60 MPa"]),
    ("mc=20", ["oak MC 20% 120 MPa", "oak MC 20% 60 MPa"]),
    ("mc=8, sigma_z=120", ["oak MC 8% 120 MPa"]),
])
def test_a_selector_holds_out_every_variant_it_matches(sel, labels):
    _, held, _ = paper_problem(["oak"], sel)
    assert sorted(c.label for c in held) == labels


def test_a_material_can_be_held_out_whole():
    test = held_out_selector("material=birch")
    assert test(Condition(60e6, 20, "birch")) and not test(Condition(60e6, 20, "oak"))
    data, held, _ = paper_problem(["oak", "birch"], "material=birch")
    assert {c.material for c in held} == {"birch"} and len(held) == 4


def test_shared_base_parameters_join_the_bonds_per_material():
    _, _, bounds = paper_problem(["oak"], DEFAULT_HELD_OUT, ["k1=3e4:2e5", "contact.mu=0.2:0.8"])
    assert bounds["k1"] == (3e4, 2e5) and bounds["contact.mu"] == (0.2, 0.8) and "E_b[oak]" in bounds


@pytest.mark.parametrize("sel,msg", [
    ("mc", "expected key=value"), ("colour=red", "expected key=value"), ("mc=wet", "not a number"),
    ("mc=20,mc=8", "given twice"), ("sigma_z=90", "selects none"), ("material=oak", "selects every variant"),
    ("sigma_z=nan", "must be finite"),
])
def test_a_bad_selector_names_itself(sel, msg):
    with pytest.raises(ValueError, match=msg):
        paper_problem(["oak"], sel)


@pytest.mark.parametrize("item,msg", [
    ("k1", "NAME=LO:HI"), ("k1=3e4", "NAME=LO:HI"), ("E_b=1e8:1e9", "per material already"),
    ("k1=a:b", "must be numbers"), ("k1=2e5:3e4", "LO < HI"), ("k1=-1:3", "0 < LO < HI"),
    ("contact.moisture_yield=-2:0.1", "moisture_yield"), ("k1=1:inf", "finite"),
    ("sigma_z=1e7:2e8", "allowed"), ("colour=1:2", "allowed"), ("contact.nope=1:2", "no such contact law"),
    ("contact.mu=0.2:20", "mu"),
])
def test_a_bad_shared_parameter_names_itself(item, msg):
    with pytest.raises(ValueError, match=msg):
        shared_bounds([item])
    with pytest.raises(ValueError, match="given twice"):
        shared_bounds(["k1=3e4:2e5", "k1=4e4:2e5"])


def test_the_command_line_passes_the_selector_and_shared_parameters_on():
    args = _args("--data", "paper", "--held-out", "sigma_z=60", "--fit", "k1=3e4:2e5")
    loop_cli._check(args)
    data, held, bounds, *_ = loop_cli._problem(args)
    assert sorted(c.label for c in held) == ["oak MC 20% 60 MPa", "oak MC 8% 60 MPa"] and bounds["k1"] == (3e4, 2e5)
    # a manifest says both itself; synthetic data have theirs
    for extra in (("--data", "example", "--held-out", "mc=20"), ("--synthetic", "none", "--fit", "k1=3e4:2e5")):
        with pytest.raises(ValueError, match="for --data paper"):
            loop_cli._check(_args(*extra))
    with pytest.raises(ValueError, match="selects none"):
        loop_cli._check(_args("--data", "paper", "--held-out", "mc=12"))


@pytest.mark.parametrize("extra,flag", [
    (("--data", "paper", "--set", "contact.moisture_content=12"), "--set"),
    (("--data", "paper", "--fit", "contact.moisture_content=5:20"), "--fit"),
    (("--synthetic", "contact.moisture_content=20"), "--synthetic"),
])
def test_the_moisture_content_is_the_conditions_not_a_setting(extra, flag):
    with pytest.raises(ValueError, match=f"{flag}.*contact.moisture_content is set by each condition"):
        loop_cli._check(_args(*extra))


def test_a_signed_law_row_is_fitted_across_zero():
    assert shared_bounds(["contact.moisture_yield=-0.05:0.1"]) == {"contact.moisture_yield": (-0.05, 0.1)}


def test_each_material_s_particles_have_its_wood_s_density():
    from pelletdem.loop_paper import particle_densities
    from pelletdem.presets import get_preset

    rho = particle_densities(["oak", "birch", "pine"])
    assert rho == {"oak": 675.0, "birch": 550.0, "pine": 510.0}  # Table 2, BD_w at MC 8 %
    # Table 4's particle density is oak's
    assert rho["oak"] == pytest.approx(get_preset("tiny").density, rel=0.01)
    with pytest.raises(ValueError, match="spruce"):
        particle_densities(["spruce"])


def test_the_paper_s_pellets_run_with_the_wider_overlap_guard():
    from pelletdem.loop_paper import PAPER_OVERLAP_GUARD, paper_preset
    from pelletdem.presets import get_preset

    args = _args("--data", "paper", "--preset", "quick")
    preset = loop_cli._problem(args)[6]
    assert preset.max_overlap_ratio == PAPER_OVERLAP_GUARD == 2.0
    assert preset == get_preset("quick").with_(max_overlap_ratio=2.0)
    assert paper_preset("tiny").n_particles == get_preset("tiny").n_particles
    # other data keep the preset's own guard
    assert loop_cli._problem(_args("--synthetic", "none"))[6] == "tiny"
