"""Tests of pelletdem.metrics against hand-computed values."""

import math

import numpy as np
import pytest

from pelletdem import measured, metrics

# --------------------------------------------------------------------------------------
# rrmse (eq. 16)
# --------------------------------------------------------------------------------------


def test_rrmse_hand_case():
    # relative errors (1 - 1.1)/1 = -0.1, (2 - 1.8)/2 = 0.1, 0
    expected = math.sqrt((0.01 + 0.01 + 0) / 3)
    assert metrics.rrmse([1, 2, 4], [1.1, 1.8, 4]) == pytest.approx(expected, rel=1e-12)


def test_rrmse_divides_by_the_measured_value():
    assert metrics.rrmse([2.0], [1.0]) == pytest.approx(0.5)
    assert metrics.rrmse([1.0], [2.0]) == pytest.approx(1.0)


def test_rrmse_is_scale_free():
    a = metrics.rrmse([1.0, 2.0, 4.0], [1.1, 1.8, 4.4])
    assert metrics.rrmse([1e6, 2e6, 4e6], [1.1e6, 1.8e6, 4.4e6]) == pytest.approx(a, rel=1e-12)


def test_rrmse_zero_for_identical():
    assert metrics.rrmse(np.array([3.0, 5.0]), np.array([3.0, 5.0])) == 0.0


def test_rrmse_shape_mismatch():
    with pytest.raises(ValueError, match="shape mismatch"):
        metrics.rrmse([1, 2, 3], [1, 2])


def test_rrmse_zero_measured_names_index():
    with pytest.raises(ValueError, match=r"measured\[1\] is 0"):
        metrics.rrmse([1, 0, 3], [1, 2, 3])


@pytest.mark.parametrize("which", ["measured", "simulated"])
def test_rrmse_nan_names_index(which):
    good, bad = [1.0, 2.0, 3.0], [1.0, 2.0, float("nan")]
    args = (bad, good) if which == "measured" else (good, bad)
    with pytest.raises(ValueError, match=rf"{which}\[2\]"):
        metrics.rrmse(*args)


def test_rrmse_empty():
    with pytest.raises(ValueError, match="empty"):
        metrics.rrmse([], [])


# --------------------------------------------------------------------------------------
# rrmse_curve
# --------------------------------------------------------------------------------------


def test_rrmse_curve_uniform_ten_percent_error():
    mx = np.array([0.01, 0.02, 0.03, 0.04, 0.05])
    # sim is 10% high everywhere and sampled only at its ends: linear interpolation is exact
    assert metrics.rrmse_curve(mx, 1e6 * mx, [0.0, 0.1], [0.0, 1.1e5]) == pytest.approx(0.1, rel=1e-12)


def test_rrmse_curve_interpolates_at_measured_x():
    # sim at x = 0.01 is 1 (midway 0 -> 2), at 0.03 is 2 (flat)
    r = metrics.rrmse_curve([0.01, 0.03], [2.0, 2.5], [0.0, 0.02, 0.04], [0.0, 2.0, 2.0])
    assert r == pytest.approx(math.sqrt((0.5 ** 2 + 0.2 ** 2) / 2), rel=1e-12)


def test_rrmse_curve_uses_only_covered_points():
    mx = [0.01, 0.02, 0.03, 0.04]
    my = [1.0, 2.0, 3.0, 40.0]  # the last point is far off but not covered by the simulation
    # sim covers [0, 0.025]: exactly half of the measured range 0.01-0.04; y = 100 x + 0.1
    r = metrics.rrmse_curve(mx, my, [0.0, 0.025], [0.1, 2.6], min_fraction_of_peak=0)
    assert r == pytest.approx(math.sqrt(((0.1 / 1.0) ** 2 + (0.1 / 2.0) ** 2) / 2), rel=1e-9)


def test_rrmse_curve_insufficient_overlap():
    with pytest.raises(ValueError, match=r"covers only 33% .*at least 50%"):
        metrics.rrmse_curve([0.01, 0.02, 0.03, 0.04], [1, 2, 3, 4], [0.0, 0.02], [0, 2])


def test_rrmse_curve_x_range():
    mx = np.array([0.01, 0.02, 0.03, 0.04])
    my = np.array([1.0, 2.0, 3.0, 4.0])
    sim_y = np.array([0.0, 1.0, 2.0, 3.0, 8.0])  # exact up to 0.03, wrong at 0.04
    sim_x = np.array([0.0, 0.01, 0.02, 0.03, 0.04])
    assert metrics.rrmse_curve(mx, my, sim_x, sim_y, x_range=(0.0, 0.035)) == 0.0
    assert metrics.rrmse_curve(mx, my, sim_x, sim_y) == pytest.approx(math.sqrt(1.0 / 4))


def test_rrmse_curve_drops_the_toe_by_default():
    mx = [0.0, 0.01, 0.02, 0.03]
    my = [0.0, 1.0, 2.0, 3.0]
    assert metrics.rrmse_curve(mx, my, [0.0, 0.03], [0.0, 3.0]) == 0.0
    with pytest.raises(ValueError, match=r"measured\[0\] is 0"):
        metrics.rrmse_curve(mx, my, [0.0, 0.03], [0.0, 3.0], min_fraction_of_peak=0)


def test_rrmse_curve_toe_cut_is_relative_to_peak():
    # 0.04 < 5% of 1.0 is dropped; its huge relative error would otherwise count
    mx, my = [0.01, 0.02, 0.03], [0.04, 0.5, 1.0]
    sim_x, sim_y = [0.0, 0.01, 0.02, 0.03], [0.0, 0.4, 0.5, 1.0]
    assert metrics.rrmse_curve(mx, my, sim_x, sim_y) == 0.0
    assert metrics.rrmse_curve(mx, my, sim_x, sim_y, min_fraction_of_peak=0) > 4.0


def test_rrmse_curve_rejects_decreasing_sim_x():
    with pytest.raises(ValueError, match=r"sim_x\[2\]"):
        metrics.rrmse_curve([0.01, 0.02], [1, 2], [0.0, 0.03, 0.02], [0, 3, 2])


def test_rrmse_curve_rejects_nan_in_curve():
    with pytest.raises(ValueError, match=r"sim_y\[1\]"):
        metrics.rrmse_curve([0.01, 0.02], [1, 2], [0.0, 0.03], [0, float("nan")])


# --------------------------------------------------------------------------------------
# rrmse_replicates
# --------------------------------------------------------------------------------------


def _replicates():
    x = np.linspace(0.01, 0.1, 10)
    return measured.Curve(np.r_[x, x], np.r_[1e6 * x, 3e6 * x], replicate=["a"] * 10 + ["b"] * 10)


def test_rrmse_replicates_by_hand():
    sim_x = np.array([0.0, 0.1])
    res = metrics.rrmse_replicates(_replicates(), sim_x, 2e6 * sim_x)
    assert res.replicate == ("a", "b")
    # a: (1 - 2) / 1 -> 1; b: (3 - 2) / 3 -> 1/3 at every point
    np.testing.assert_allclose(res.per_replicate, [1.0, 1.0 / 3.0], rtol=1e-12)
    assert res.mean == pytest.approx(2.0 / 3.0)
    assert res.sd == pytest.approx((1.0 - 1.0 / 3.0) / math.sqrt(2))
    assert res.mean_curve == pytest.approx(0.0, abs=1e-12)  # the mean curve is 2e6 x
    assert res.noise_floor == pytest.approx(2.0 / 3.0)


def test_rrmse_replicates_single_replicate_has_no_spread():
    x = np.linspace(0.01, 0.1, 10)
    c = measured.Curve(x, 1e6 * x)
    res = metrics.rrmse_replicates(c, [0.0, 0.1], [0.0, 1.1e5])
    assert res.per_replicate == pytest.approx([0.1])
    assert math.isnan(res.sd) and math.isnan(res.noise_floor)
    assert res.mean_curve == pytest.approx(0.1)


def test_rrmse_replicates_names_replicate_on_poor_overlap():
    x = np.linspace(0.01, 0.1, 10)
    c = measured.Curve(np.r_[x, 3 * x], np.r_[1e6 * x, 1e6 * x], replicate=["a"] * 10 + ["long"] * 10)
    with pytest.raises(ValueError, match="replicate 'long'"):
        metrics.rrmse_replicates(c, [0.0, 0.1], [0.0, 1e5])


# --------------------------------------------------------------------------------------
# sd_weighted_error
# --------------------------------------------------------------------------------------


def test_sd_weighted_error_by_hand():
    v = measured.variant("oak", 8, 120)
    res = metrics.sd_weighted_error([v.sigma_f, v.dLf_D, v.bd_pellet],
                                    [v.sigma_f_sd, v.dLf_D_sd, v.bd_pellet_sd],
                                    [1.2e6, 0.07, 1005.8])
    z = [(1.2e6 - 1.346e6) / 0.068e6, (0.07 - 0.061) / 0.003, 0.0]
    np.testing.assert_allclose(res.z, z, rtol=1e-9, atol=1e-12)
    assert res.rms == pytest.approx(math.sqrt(sum(zi * zi for zi in z) / 3), rel=1e-9)


def test_sd_weighted_error_floor():
    # SD 0: the 1% floor makes the SD 1.0 for a mean of 100
    res = metrics.sd_weighted_error(100.0, 0.0, 101.0)
    assert res.sd_used.tolist() == [1.0] and res.z.tolist() == [1.0]
    # an SD above the floor is used as is
    assert metrics.sd_weighted_error(100.0, 4.0, 102.0).z.tolist() == [0.5]
    assert metrics.sd_weighted_error(100.0, 0.0, 101.0, rel_sd_floor=0.1).z.tolist() == [pytest.approx(0.1)]
    assert metrics.sd_weighted_error(0.0, 0.0, 1.0, abs_sd_floor=0.5).z.tolist() == [2.0]


def test_sd_weighted_error_rejects_bad_input():
    with pytest.raises(ValueError, match="even after the floor"):
        metrics.sd_weighted_error(0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match=r"measured_sd\[1\]"):
        metrics.sd_weighted_error([1.0, 2.0], [0.1, -0.1], [1.0, 2.0])
    with pytest.raises(ValueError, match="shape mismatch"):
        metrics.sd_weighted_error([1.0, 2.0], [0.1, 0.1], [1.0])
    with pytest.raises(ValueError, match=r"simulated\[0\]"):
        metrics.sd_weighted_error([1.0], [0.1], [float("nan")])


@pytest.mark.parametrize("fn", [metrics.rrmse, metrics.rrmse_curve, metrics.rrmse_replicates,
                                metrics.sd_weighted_error])
def test_public_functions_document_units(fn):
    doc = fn.__doc__ or ""
    assert "Pa" in doc or "dimensionless" in doc or "(-)" in doc
