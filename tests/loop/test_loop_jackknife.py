"""What a fit owes to its own packings: the jackknife over the fit seeds (pelletdem.loop_jackknife)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop import Condition, Dataset, Observation
from pelletdem.loop_emulator import Axis, Emulator, Space, design
from pelletdem.loop_fit import fit_emulated
from pelletdem.loop_jackknife import packing_jackknife, with_packing_luck
from pelletdem.loop_noise import PackingNoise

SLOPE = 2.0   # d(output)/du of every output
TRUTH = 0.4   # the data's position in the unit box


def _luck_case(offsets, n_out=3, data_se=0.05):
    """A one-parameter model whose outputs are -10 + SLOPE u (linear, so emulated exactly),
    simulated on packings that each shift every output by its own offset at every design
    point (common random numbers); data at u = TRUTH, error-free mean, SE ``data_se``."""
    space = Space((Axis("g", 0.0, 1.0, log=False),))
    U = design(1, 16)
    c = np.asarray(offsets, float)
    members = (-10.0 + SLOPE * U[:, :1, None] + c[None, :, None]) * np.ones((1, 1, n_out))
    Y = members.mean(axis=1)
    SE = members.std(axis=1, ddof=1) / math.sqrt(len(c))
    cond = Condition(120e6)
    obs = [Observation(cond, "sigma_z", 0.1 * (i + 1), -10.0 + SLOPE * TRUTH, data_se * math.sqrt(5), 5)
           for i in range(n_out)]
    data = Dataset(obs)
    return space, Emulator(space, U, Y, SE), members, data


def test_the_jackknife_of_a_linear_fit_is_the_squared_standard_error_of_the_packings_mean_offset():
    # every output moves with the packing's offset, so the fit moves by -offset / SLOPE: the
    # jackknife variance is var(offsets) / k / SLOPE^2, and the fit itself sits at
    # TRUTH - mean(offsets) / SLOPE
    offsets = np.array([0.30, -0.10, 0.05, 0.15])
    space, emu, members, data = _luck_case(offsets)
    fit = fit_emulated(emu, data, starts=2)
    assert fit.u[0] == pytest.approx(TRUTH - offsets.mean() / SLOPE, abs=5e-3)
    jack = packing_jackknife(emu, members, data, fit.u)
    expected = np.var(offsets, ddof=1) / len(offsets) / SLOPE ** 2
    assert jack.shape == (1, 1)
    assert jack[0, 0] == pytest.approx(expected, rel=0.05)


def test_no_jackknife_from_too_few_packings_or_members_that_do_not_match():
    space, emu, members, data = _luck_case([0.1, -0.1])
    assert packing_jackknife(emu, members, data, np.array([0.5])) is None
    space, emu, members, data = _luck_case([0.1, -0.1, 0.2])
    assert packing_jackknife(emu, members[:-1], data, np.array([0.5])) is None


def test_the_fit_packings_luck_widens_the_errors_only_where_the_jackknife_exceeds_the_correlation():
    space, emu, members, data = _luck_case(np.array([0.30, -0.10, 0.05, 0.15]))
    fit = fit_emulated(emu, data, starts=2)
    noise = PackingNoise.independent()
    small = with_packing_luck(fit, emu, data, noise, 4, np.zeros((1, 1)))
    assert small.se == fit.se and small.widen == fit.widen
    big = 10.0 * fit.cov
    wide = with_packing_luck(fit, emu, data, noise, 4, big)
    # the data's part of the sandwich plus the jackknife, which here outweighs the model's part
    J = fit.jac
    plain = np.linalg.pinv(J.T @ J)
    c_data, c_model = noise.covariance_parts(data, emu.noise(), emu.noise() * 2.0)
    d = np.sqrt(np.diag(c_data + c_model))
    v_data = float((plain @ J.T @ (c_data / np.outer(d, d)) @ J @ plain)[0, 0])
    assert wide.cov[0, 0] == pytest.approx(v_data + big[0, 0], rel=1e-9)
    assert wide.se["g"] == pytest.approx(math.sqrt(v_data + big[0, 0]), rel=1e-9)
    assert wide.widen["g"] == pytest.approx((v_data + big[0, 0]) / plain[0, 0], rel=1e-9)
    assert wide.interval("g")[1] - wide.interval("g")[0] > fit.interval("g")[1] - fit.interval("g")[0]
    assert with_packing_luck(fit, emu, data, noise, 4, None) is fit


def test_the_covariance_is_its_data_and_model_parts():
    space, emu, members, data = _luck_case([0.1, -0.1, 0.2])
    noise = PackingNoise.independent()
    se = np.full(len(data), 0.03)
    c_data, c_model = noise.covariance_parts(data, se, se * 2.0)
    assert np.allclose(c_data + c_model, noise.covariance(data, se, se * 2.0))
    assert np.allclose(c_model, np.diag(se ** 2))


def test_a_fitted_model_keeps_its_packings_and_measures_their_luck():
    # sigma_f = 0.1 sigma_c (1 + eps_s) with a luck eps_s per packing, the same at every
    # parameter set: the fit of ln(sigma_c) owes var(ln(1 + eps)) / k to the fit packings
    from pelletdem.loop import FunctionSimulator, Prediction
    from pelletdem.loop_models import fit_model, nested_points

    luck = {0: 0.06, 1: -0.02, 2: 0.01, 3: 0.03}

    def pellet(params, cond, seed):
        return Prediction(scalars={"sigma_f": 0.1 * params["sigma_c"] * (1.0 + luck.get(seed, 0.0)),
                                   "bulk_density": 600.0 + 1e-7 * params["E_b"] + 5.0 * luck.get(seed, 0.0)})

    cond = Condition(120e6)
    data = Dataset([Observation(cond, "sigma_f", math.nan, 1.0e6, 2e4, 5),
                    Observation(cond, "bulk_density", math.nan, 605.0, 2.0, 5)])
    space = Space((Axis("E_b", 1e7, 1e9), Axis("sigma_c", 1e6, 1e8)))
    sim = FunctionSimulator(pellet, default_seeds=(0, 1, 2, 3))
    mf = fit_model(sim, space, (), data, None, (0, 1, 2, 3), (10, 11), n_design=16, refine=0)
    assert mf.members.shape == (len(mf.emulator.U), 4, len(data))
    assert np.allclose(mf.members.mean(axis=1), mf.emulator.Y)
    eps = np.log1p(np.array(list(luck.values())))
    expected = np.var(eps, ddof=1) / 4 / math.log(100.0) ** 2
    assert mf.fit.jackknife[1, 1] == pytest.approx(expected, rel=0.15)
    # a candidate's box takes the baseline's points with their packings
    U, Y, SE, V = nested_points(mf, 0.0)
    assert V is mf.members and len(U) == len(V)
