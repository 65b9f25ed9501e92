"""The time step guard (cpp/src/time_step.cpp): dt is refused above TIME_STEP_SAFETY of the
stability limit of the stiffest spring the contact law, its effects and the bonds can reach
over the range they allow, and the refusal names that spring.

The chosen model of the calibration (docs/calibration.md, run R) unloads at k_p = 50 k2 =
4.8e6 N/m once compaction has flattened its contacts; the guard of the paper's law alone
(k2 = 9.6e4 N/m) allowed 4.06e-5 s, and dt = 4e-6 and 6e-6 s passed it and ran unstably
(6e-6: a peak density of 2,392 kg/m^3)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd
from effects.test_hardening import _drive
from pelletdem import presets, stages
from test_contact_law import R, frictionless

# Run R's law (docs/calibration.md, "The chosen model"): oak's k1, the shared rows.
CHOSEN_LAW = dict(k1=1.504e4, k2=9.6e4, plastic_stiffness_ratio=50.0, moisture_yield=-0.0398, hardening=0.68,
                  hardening_exponent=2.0, densified_yield=100.0, interlocking_friction=2.0)


def _world(law, dt=1e-7, radius=R, n=2, max_overlap_ratio=0.9, **kw):
    """`n` spheres of `radius` in a row along x, touching, no gravity."""
    w = pd.World(dt=dt, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)), contact=law, gravity=(0, 0, 0),
                 skin=2e-5, max_overlap_ratio=max_overlap_ratio, **kw)
    x = np.array([[(2 * k - (n - 1)) * radius, 0.0, 0.0] for k in range(n)])
    w.add_particles(x, np.full(n, radius))
    return w


def _spring(w, starts):
    """The one spring of ``w.time_step_springs()`` whose description starts with ``starts``."""
    found = [s for s in w.time_step_springs() if s["what"].startswith(starts)]
    assert len(found) == 1, [s["what"] for s in w.time_step_springs()]
    return found[0]


@pytest.mark.parametrize("dt", [4e-6, 6e-6])
def test_the_chosen_model_refuses_the_steps_that_ran_unstably(dt):
    """On the preset's lightest particle (radius_min, the scaled density) and with the overlap
    guard R ran at, dt = 4e-6 and 6e-6 s are refused, naming k_p; 2e-6 s is accepted."""
    p = presets.get_preset("tiny")
    law = pd.ContactLaw(**CHOSEN_LAW)
    kw = dict(radius=p.radius_min, max_overlap_ratio=2.0, density=p.density, density_scale=p.density_scale)
    with pytest.raises(pd.ParameterError, match=(
            rf"dt = {dt:g} s is above the stable time step: allowed 0 < dt <= 2\.8\d+e-06 s, 0\.5 of the "
            r"stability limit .* between two particles: normal unloading stiffness k_p = "
            r"plastic_stiffness_ratio x k2 = 4\.8e\+06 N/m")):
        _world(law, dt=dt, **kw)
    w = _world(law, dt=p.dt, **kw)
    m = w.masses()[0]
    assert w.critical_time_step() == pytest.approx(2 * math.sqrt((m / 2) / 4.8e6), rel=1e-12)
    assert p.dt <= w.max_time_step() < 4e-6


@pytest.mark.parametrize("dt,release_damping,refused", [(4e-6, 0.3, True), (2.8e-6, 0.3, True),
                                                         (2.8e-6, 0.0, False)])
def test_the_fill_refuses_a_step_that_a_later_stage_makes_unstable(monkeypatch, dt, release_damping, refused):
    """The bed settles under a law without the compaction effects (stages.fill_law), whose
    step is far larger; the fill checks the later stages' laws before it steps. 2.8e-6 s holds
    k_p undamped (2.87e-6) but not with the relaxation's damping (0.3 of critical on k2)."""
    p = presets.get_preset("tiny").with_(contact=pd.ContactLaw(**CHOSEN_LAW), max_overlap_ratio=2.0, dt=dt,
                                         release_damping_ratio=release_damping)
    ran = []

    class Stepped(Exception):
        pass

    def first_step(pellet, name, *args, **kwargs):
        ran.append(name)
        raise Stepped

    monkeypatch.setattr(stages, "_run", first_step)
    expected = pd.ParameterError if refused else Stepped
    with pytest.raises(expected, match=r"k_p = plastic_stiffness_ratio x k2" if refused else None):
        stages.fill(p, progress=False)
    assert ran == ([] if refused else ["fill"])


def test_the_diametral_stages_law_is_guarded_too():
    """densified_yield x 100 makes the loading line steeper than every unloading one: it is
    followed at the unloading stiffness, so k_p still sets the limit."""
    w = _world(pd.ContactLaw(**CHOSEN_LAW))
    loading = _spring(w, "between two particles: normal loading tangent")
    assert "k1 x 100 (the effects' factor on k1)" in loading["what"]
    assert "followed at the unloading stiffness" in loading["what"]
    assert loading["k"] == pytest.approx(4.8e6)
    assert w.critical_time_step() == pytest.approx(_spring(w, "between two particles: normal unloading")["dt_limit"])


def test_a_steeper_loading_line_is_followed_at_the_unloading_stiffness():
    """The guard's premise (HystereticLaw::normal_force): however steep the loading branch
    (hardening 1e3, a tangent of up to ~100 k2 here), the force of a pair pressed together
    rises at no more than k2 per unit of overlap."""
    law = frictionless(1.0e5, 4.0e5)
    law.hardening = 1.0e3
    d, f = _drive(law, [(0.01, 3000)]).T
    assert d[-1] > 0.02 * R  # the hardened tangent k1 (1 + 2 h d / r*) exceeds k2 tenfold there
    slope = np.diff(f) / np.diff(d)
    assert slope.max() <= 4.0e5 * (1 + 1e-6)
    assert slope[-100:].min() == pytest.approx(4.0e5, rel=1e-6)  # on the unloading line at the end


@pytest.mark.parametrize("row,value,starts,expected", [
    # k_p = ratio k2, reached once delta0 = phi r*
    ("plastic_stiffness_ratio", 1000.0, "between two particles: normal unloading", lambda x: 1000.0 * 4e5),
    # k2 (1 + g x_max), x_max = 2 max_overlap_ratio: the largest delta0 / r* the overlap guard lets through
    ("unloading_growth", 5.0, "between two particles: normal unloading", lambda x: 4e5 * (1 + 5.0 * x)),
    # k1 (1 + h (n + 1) x^n) with n = 1, below k2 at x_max = 1.8
    ("hardening", 0.5, "between two particles: normal loading", lambda x: 1e5 * (1 + 0.5 * 2 * x)),
])
def test_each_effect_reports_its_stiffest_spring(row, value, starts, expected):
    w = _world(pd.ContactLaw(**{row: value}))
    assert _spring(w, starts)["k"] == pytest.approx(expected(2 * 0.9), rel=1e-12)
    w.set_max_overlap_ratio(0.45)  # a tighter guard bounds the overlap-driven springs lower
    if row != "plastic_stiffness_ratio":
        assert _spring(w, starts)["k"] == pytest.approx(expected(2 * 0.45), rel=1e-12)


def test_a_looser_overlap_guard_is_refused_if_it_would_not_hold_dt():
    """The overlap guard bounds the springs that grow with overlap, so raising it can make the
    present dt unstable: refused, the old guard kept."""
    law = pd.ContactLaw(unloading_growth=100.0)
    w = _world(law, dt=1e-7)
    w.dt = 0.99 * w.max_time_step()
    with pytest.raises(pd.ParameterError, match=r"unloading_growth x the largest overlap"):
        w.set_max_overlap_ratio(5.0)
    assert w.max_overlap_ratio == 0.9


def test_damping_lowers_the_limit_as_velocity_verlet_needs():
    """omega dt < 2 (sqrt(1 + zeta^2) - zeta): normal damping is a fraction of critical on k2."""
    plain = _world(frictionless(1e5, 4e5))
    damped = _world(pd.ContactLaw(k1=1e5, k2=4e5, mu=0.0, mu_wall=0.0, rolling=0.0, normal_damping_ratio=0.3))
    a, b = (_spring(w, "between two particles: normal unloading") for w in (plain, damped))
    assert b["zeta"] == pytest.approx(0.3)
    assert b["dt_limit"] == pytest.approx(a["dt_limit"] * (math.sqrt(1 + 0.09) - 0.3), rel=1e-12)


def _oscillate_on_k_p(law, periods, dt=None):
    """A pair pressed until its contact saturates, then let go: the largest kinetic energy of
    each of ``periods`` periods of the k_p line (J), the force it was let go at (N) and k_p."""
    w = _world(law, dt=1e-8)
    v = 0.01
    for _ in range(2000):  # pressed together on the loading line, far past phi r*
        w.set_velocities(np.array([[v, 0, 0], [-v, 0, 0]]), np.zeros((2, 3)))
        w.step()
    f_max = w.contacts()["fn"][0]
    w.set_velocities(np.zeros((2, 3)), np.zeros((2, 3)))
    k_p = law.plastic_stiffness_ratio * law.k2
    assert w.critical_time_step() == pytest.approx(2 * math.sqrt((w.masses()[0] / 2) / k_p), rel=1e-12)
    w.dt = w.max_time_step() if dt is None else dt
    steps = int(round(2 * math.pi / math.sqrt(k_p / (w.masses()[0] / 2)) / w.dt))
    peaks = []
    for _ in range(periods):
        ke = 0.0
        for _ in range(steps):
            w.step()
            ke = max(ke, w.kinetic_energy())
        peaks.append(ke)
    assert w.contact_count == 1
    return np.array(peaks), f_max, k_p


def test_energy_with_saturating_unloading_at_its_box_top():
    """k_p at the top of its box (1000 k2): a pair let go from the saturated loading line
    oscillates on the k_p line (adhesion kc = 2 k1 holds it bound; nothing dissipates). With a
    fine step its kinetic energy peaks at what the line held, 0.5 f^2 / k_p; at the largest dt
    the guard accepts (omega dt = 1, about six steps a period, where the paper's guard on k2
    alone allowed 30 times more) velocity Verlet samples the peak lower but keeps it: no growth
    over 200 periods."""
    law = frictionless(1.0e5, 4.0e5, kc=2.0e5)
    law.plastic_stiffness_ratio, law.plastic_overlap = 1000.0, 1e-3
    fine, f_max, k_p = _oscillate_on_k_p(law, 3, dt=1e-9)
    np.testing.assert_allclose(fine, 0.5 * f_max**2 / k_p, rtol=2e-3)
    peaks, _, _ = _oscillate_on_k_p(law, 200)
    assert 0.5 < peaks.min() / fine.max() and peaks.max() / fine.max() < 1.0
    assert peaks.max() / peaks.min() < 1.01


def test_stiff_bonds_are_refused_when_made_and_the_world_left_unbonded():
    w = _world(frictionless(1e5, 4e5), dt=2e-6, density_scale=1e4, n=2)
    w.set_positions(w.x - np.array([[-1e-6, 0, 0], [1e-6, 0, 0]]))  # touching, so a bond is made
    with pytest.raises(pd.ParameterError, match=r"dt = 2e-06 s is above the stable time step.* a bond"):
        w.create_bonds(pd.BondLaw(radius=2e-4, youngs_modulus=1e11).to_core())
    assert w.bonds()["i"].size == 0
    assert w.create_bonds(pd.BondLaw().to_core()) == 1  # Table 4/5's bonds: the step holds
    assert len([s for s in w.time_step_springs() if s["what"].startswith("a bond")]) == 3


def test_a_bond_made_stiffer_afterwards_is_refused_before_the_next_step():
    w = _world(frictionless(1e5, 4e5), dt=2e-6, density_scale=1e4, n=2)
    w.set_positions(w.x - np.array([[-1e-6, 0, 0], [1e-6, 0, 0]]))
    assert w.create_bonds(pd.BondLaw().to_core()) == 1
    w.step()
    w.set_bond_property("kn", [1e20])  # N/m^3: a bond far stiffer than the step can hold
    for advance in (w.step, lambda: w.run(1)):
        with pytest.raises(pd.ParameterError, match=r"above the stable time step.* a bond with its contact: axial"):
            advance()
    w.set_bond_property("kn", [1e9])
    w.step()


def test_the_loops_runs_get_a_stable_step_and_keep_their_bed():
    """A run whose law the preset's dt cannot hold (unloading_growth 10 on `tiny`: k2 (1 + 10 x
    2 x 1.5) = 31 k2) gets the stable step, rounded down, for its stages and settles its bed
    at the preset's: the same bed as the base law's, to the bit; a law the dt holds keeps it."""
    from pelletdem import runs

    base = runs.make_spec(preset="tiny").preset
    stiff = runs.make_spec({"contact.unloading_growth": 10.0}, preset="tiny").preset
    assert base.dt == 2e-6 and base.fill_dt == 0.0
    assert stiff.fill_dt == 2e-6 and stiff.dt < 2e-6
    assert stiff.dt <= stages.stable_time_step(stiff) < 1.1 * stiff.dt
    stages.check_time_step(stiff)  # its stages hold the step
    with pytest.raises(pd.ParameterError, match=r"unloading_growth x the largest overlap"):
        stages.check_time_step(stiff.with_(dt=2e-6, fill_dt=0.0))
    beds = [stages.fill(p, seed=3, progress=False)[0].world for p in (base, stiff)]
    np.testing.assert_array_equal(beds[0].x, beds[1].x)
    assert beds[1].dt == stiff.dt
