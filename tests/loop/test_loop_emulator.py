"""The Gaussian-process emulator and its box (pelletdem.loop_emulator)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop_emulator import Axis, Emulator, Space, design


def test_axis_maps_its_range_to_the_unit_interval_both_ways():
    a = Axis("E_b", 1e6, 1e9)
    assert a.to_unit(1e6) == pytest.approx(0.0) and a.to_unit(1e9) == pytest.approx(1.0)
    assert a.to_unit(math.sqrt(1e6 * 1e9)) == pytest.approx(0.5)  # log axis: the geometric mean
    lin = Axis("x", -0.2, 0.2, log=False)
    assert lin.from_unit(0.75) == pytest.approx(0.1)
    for u in (0.0, 0.3, 1.0):
        assert a.to_unit(a.from_unit(u)) == pytest.approx(u)
    with pytest.raises(ValueError, match="E_b"):
        Axis("E_b", 0.0, 1.0)
    with pytest.raises(ValueError, match="lo < hi"):
        Axis("x", 1.0, 1.0, log=False)


def test_space_adds_a_candidate_axis_and_its_fixed_settings():
    s = Space((Axis("E_b", 1e6, 1e9),)).with_axis(Axis("contact.hardening", 0.05, 200.0),
                                                  {"contact.hardening_exponent": 2.0})
    p = s.params([0.5, 0.0])
    assert p["contact.hardening"] == pytest.approx(0.05) and p["contact.hardening_exponent"] == 2.0
    assert s.names == ["E_b", "contact.hardening"] and s.dim == 2


def test_design_is_space_filling_reproducible_and_checked():
    U = design(2, 16)
    assert U.shape == (16, 2) and np.all((U >= 0) & (U <= 1))
    assert np.array_equal(U, design(2, 16))
    # every quarter of each axis holds a quarter of a balanced Sobol set
    for j in range(2):
        assert np.all(np.histogram(U[:, j], bins=4, range=(0, 1))[0] == 4)
    with pytest.raises(ValueError, match="design points"):
        design(2, 1)


def _truth(U):
    return np.column_stack([np.exp(1.0 + U[:, 0]) * (1 + 0.5 * U[:, 1]), 3.0 * U[:, 1] - 1.0])


def test_emulator_predicts_a_smooth_response_between_its_design_points():
    rng = np.random.default_rng(0)
    space = Space((Axis("a", 0.0, 1.0, log=False), Axis("b", 0.0, 1.0, log=False)))
    U = design(2, 24)
    Y = _truth(U)
    SE = np.column_stack([0.01 * Y[:, 0], np.full(len(U), 0.01)])  # 1 % of a positive output
    Yn = Y + SE * rng.standard_normal(Y.shape)
    emu = Emulator(space, U, Yn, SE)
    Ut = rng.uniform(0.1, 0.9, (50, 2))
    mean, var = emu.predict(Ut)
    err = np.abs(mean - _truth(Ut))
    assert np.max(err[:, 0] / _truth(Ut)[:, 0]) < 0.03
    assert np.max(err[:, 1]) < 0.05
    # the reported uncertainty covers the error (a few sigma)
    assert np.all(err < 5 * np.sqrt(var) + 0.02)
    # the typical SE of an ensemble mean: relative for the positive output, absolute otherwise
    assert emu.noise()[0] == pytest.approx(0.01 * np.mean(Yn[:, 0]), rel=0.02)
    assert emu.noise()[1] == pytest.approx(0.01)


def test_emulator_takes_a_constant_output_and_refuses_mismatched_shapes():
    space = Space((Axis("a", 0.0, 1.0, log=False),))
    U = design(1, 8)
    Y = np.column_stack([np.full(8, 5.0), U[:, 0]])
    emu = Emulator(space, U, Y, np.full_like(Y, 0.01))
    mean, _ = emu.predict(np.array([[0.3]]))
    assert mean[0, 0] == pytest.approx(5.0) and mean[0, 1] == pytest.approx(0.3, abs=0.02)
    with pytest.raises(ValueError, match="disagree"):
        Emulator(space, U, Y[:4], np.full_like(Y, 0.01))


def test_fast_prediction_is_scikit_learns_latent_prediction():
    rng = np.random.default_rng(2)
    space = Space((Axis("a", 0.0, 1.0, log=False), Axis("b", 0.0, 1.0, log=False)))
    U = design(2, 16)
    Y = _truth(U) + 0.01 * rng.standard_normal((16, 2))
    emu = Emulator(space, U, Y, np.full_like(Y, 0.01))
    Ut = rng.uniform(0, 1, (7, 2))
    for j, fast in enumerate(emu._gps):
        gp_mean, gp_var = fast.predict(Ut)
        # the same GP through scikit-learn: std^2 holds the fitted white noise, the latent does not
        from sklearn.gaussian_process import GaussianProcessRegressor

        t = np.log(Y[:, j]) if emu._log[j] else Y[:, j]
        gp = GaussianProcessRegressor(kernel=fast.kernel, optimizer=None, normalize_y=True,
                                      alpha=(0.01 / (Y[:, j] if emu._log[j] else 1.0) / np.std(t)) ** 2 + 1e-10)
        gp.fit(U, t)
        mu, sd = gp.predict(Ut, return_std=True)
        white = fast.kernel.k2.noise_level * gp._y_train_std ** 2
        assert gp_mean == pytest.approx(mu, rel=1e-8, abs=1e-10)
        assert gp_var == pytest.approx(np.maximum(sd ** 2 - white, 0), rel=1e-6, abs=1e-12)


def test_an_output_emulated_over_its_own_axes_is_right_off_the_design_diagonal():
    """Two outputs, each moving with one axis (one material's bond each): a design on the
    diagonal u0 = u1 covers each output's own axis, and an emulator fitted over its own axes
    predicts them anywhere in the square; over both axes it cannot tell which one moves it."""
    space = Space((Axis("E_b[oak]", 0.0, 1.0, log=False), Axis("E_b[pine]", 0.0, 1.0, log=False)))
    u = design(1, 16)[:, 0]
    U = np.column_stack([u, u])

    def truth(U):
        return np.column_stack([np.exp(1.0 + U[:, 0]), 2.0 + np.sin(3.0 * U[:, 1])])

    SE = np.full((len(U), 2), 1e-3)
    own = Emulator(space, U, truth(U), SE, active=[(0,), (1,)])
    Ut = np.random.default_rng(1).uniform(0.05, 0.95, (40, 2))
    err = np.abs(own.predict(Ut)[0] - truth(Ut))
    assert np.max(err / truth(Ut)) < 0.01
    both = Emulator(space, U, truth(U), SE)
    assert np.max(np.abs(both.predict(Ut)[0] - truth(Ut)) / truth(Ut)) > 5 * np.max(err / truth(Ut))
    for bad in ([(0,)], [(0,), ()], [(0,), (2,)]):
        with pytest.raises(ValueError, match="active"):
            Emulator(space, U, truth(U), SE, active=bad)
