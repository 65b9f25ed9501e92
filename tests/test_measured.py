"""Tests of pelletdem.measured: shipped tables, variants, user curve files."""

import csv
import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pelletdem import measured as m

DATA = Path(m.__file__).parent / "data"


def _raw_csv(name):
    """The shipped CSV read with the csv module, independently of measured.py."""
    with open(DATA / name, newline="") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def _write(path, text):
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------------
# Shipped tables
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("n, loader, rows", [
    (1, m.solid_density, 3), (2, m.bulk_density, 6), (3, m.tensile_strength, 12),
    (4, m.dem_parameters, 29), (5, m.best_fit_dem, 12),
])
def test_load_table_matches_named_loader(n, loader, rows):
    frame = m.load_table(n)
    pd.testing.assert_frame_equal(frame, loader())
    assert len(frame) == rows


@pytest.mark.parametrize("bad", [0, 6, "1", 1.0, True])
def test_load_table_rejects_unknown_numbers(bad):
    with pytest.raises(ValueError, match="n must be one of"):
        m.load_table(bad)


def test_loaders_return_copies():
    frame = m.tensile_strength()
    frame.loc[0, "sigma_f_mpa_mean"] = -1.0
    assert m.tensile_strength().loc[0, "sigma_f_mpa_mean"] == 0.112


def test_solid_density_values():
    t1 = m.solid_density().set_index("material")
    assert t1.loc["oak", "rho_sawdust_solid_mean"] == 1459.9
    assert t1.loc["pine", "rho_wood_solid_sd"] == 0.3


def test_tensile_strength_tidy_columns_and_values():
    t3 = m.tensile_strength()
    assert list(t3.columns[:3]) == ["material", "mc_percent", "sigma_z_mpa"]
    row = t3[(t3.material == "oak") & (t3.mc_percent == 8) & (t3.sigma_z_mpa == 120)]
    assert row["sigma_f_mpa_mean"].item() == 1.346
    assert row["dLf_D_mean"].item() == 0.061


def test_best_fit_dem_values():
    t5 = m.best_fit_dem()
    assert list(t5.columns[:3]) == ["material", "mc_percent", "sigma_z_mpa"]
    row = t5[(t5.material == "birch") & (t5.mc_percent == 20) & (t5.sigma_z_mpa == 120)]
    assert row[["cn", "e_b_mpa", "sigma_c_mpa", "rrmse"]].to_numpy().tolist() == [[12.2, 22.4, 8.05, 0.039]]


def test_dem_parameters_parses_numbers_ranges_and_lists():
    t4 = m.dem_parameters().set_index("parameter")
    assert t4.loc["loading_stiffness_mean", "value"] == 1.0e5
    assert t4.loc["bond_radius", "value_min"] == 2.0e-5
    sigma_c = t4.loc["bond_tension_strength"]
    assert math.isnan(sigma_c["value"])
    assert (sigma_c["value_min"], sigma_c["value_max"]) == (3e6, 40e6)
    assert sigma_c["value_text"] == "3e6..40e6"
    cn = t4.loc["relaxed_cn_at_120_60_48_mpa"]
    assert (cn["value_min"], cn["value_max"]) == (10.5, 12.9)


def test_bulk_density_wide_and_long():
    wide = m.bulk_density()
    assert wide.shape[0] == 6
    assert wide.loc[(wide.material == "birch") & (wide.mc_percent == 20), "bd_wood_mean"].isna().all()
    long = m.bulk_density_long()
    assert list(long.columns) == ["material", "mc_percent", "state", "sigma_z_mpa",
                                  "bd_mean", "bd_sd", "porosity_mean", "porosity_sd"]
    # 3 materials x (wood at MC 8 only + sawdust x 2 MC + pellets x 2 MC x 2 pressures)
    assert len(long) == 3 * (1 + 2 + 4)
    assert set(long.loc[long.state == "wood", "mc_percent"]) == {8}
    assert long.loc[long.state != "pellet", "sigma_z_mpa"].isna().all()
    pellet = long[(long.material == "oak") & (long.mc_percent == 8) & (long.sigma_z_mpa == 120)]
    assert pellet[["bd_mean", "bd_sd", "porosity_mean", "porosity_sd"]].to_numpy().tolist() == [
        [1005.8, 11.8, 31.1, 0.4]]
    sawdust = long[(long.material == "pine") & (long.mc_percent == 20) & (long.state == "sawdust")]
    assert sawdust["bd_mean"].item() == 250.9
    # no row is duplicated
    assert not long.duplicated(["material", "mc_percent", "state", "sigma_z_mpa"]).any()


def test_bulk_density_long_covers_every_reported_cell():
    long = m.bulk_density_long()
    for rec in _raw_csv("table2_bulk_density.csv"):
        mat, mc = rec["material"], int(rec["mc_percent"])
        for p in (60, 120):
            row = long[(long.material == mat) & (long.mc_percent == mc) & (long.sigma_z_mpa == p)]
            assert row["bd_mean"].item() == float(rec[f"bd_pellet_{p}_mean"])
            assert row["porosity_sd"].item() == float(rec[f"p_pellet_{p}_sd"])


def test_table_provenance_mentions_units():
    assert "MPa" in m.table_provenance(3)
    assert "kg/m3" in m.table_provenance(1)


# --------------------------------------------------------------------------------------
# Variants
# --------------------------------------------------------------------------------------


def test_variant_oak_8_120_in_si_units():
    v = m.variant("oak", 8, 120)
    assert v.sigma_f == pytest.approx(1.346e6, rel=1e-12)
    assert v.sigma_f_sd == pytest.approx(0.068e6, rel=1e-12)
    assert v.dLf_D == 0.061 and v.dLf_D_sd == 0.003
    assert v.sigma_z == 120e6 and v.sigma_z_mpa == 120
    assert (v.bd_pellet, v.bd_pellet_sd) == (1005.8, 11.8)
    assert v.porosity_pellet == pytest.approx(0.311)
    assert (v.bd_sawdust, v.bd_sawdust_sd) == (312.6, 5.4)
    assert (v.bd_wood, v.bd_wood_sd) == (675.0, 3.0)
    assert (v.rho_sawdust_solid, v.rho_sawdust_solid_sd) == (1459.9, 1.1)
    assert v.rho_wood_solid == 1068.4
    assert v.cn == 12.9
    assert v.e_b == pytest.approx(120e6) and v.sigma_c == pytest.approx(36e6)
    assert v.rrmse == 0.111
    assert v.bd_ratio == pytest.approx(1005.8 / 675.0)
    assert v.key == ("oak", 8, 120)


def test_variant_mc20_takes_intact_wood_from_mc8_row():
    v = m.variant("pine", 20, 60)
    assert v.bd_wood == 510.0 and v.porosity_wood == pytest.approx(0.652)
    assert v.bd_sawdust == 250.9  # the MC 20 sawdust, not MC 8


def test_variant_accepts_case_and_float_forms():
    assert m.variant(" Oak ", 8.0, 120.0) == m.variant("oak", 8, 120)


def test_variant_is_frozen():
    v = m.variant("birch", 8, 60)
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.sigma_f = 0.0


def test_variants_are_the_twelve_of_table3():
    vs = m.variants()
    assert len(vs) == 12
    assert {v.key for v in vs} == set(itertools.product(("birch", "oak", "pine"), (8, 20), (60, 120)))


def test_every_variant_matches_the_csv_files():
    fits = {(r["material"], r["mc_percent"], r["sigma_z_mpa"]): r
            for r in _raw_csv("table5_best_fit_dem.csv")}
    for rec in _raw_csv("table3_tensile_strength.csv"):
        key = (rec["material"], rec["mc_percent"], rec["sigma_z_mpa"])
        v = m.variant(rec["material"], int(rec["mc_percent"]), int(rec["sigma_z_mpa"]))
        assert v.sigma_f == pytest.approx(float(rec["sigma_f_mpa_mean"]) * 1e6, rel=1e-12)
        assert v.sigma_f_sd == pytest.approx(float(rec["sigma_f_mpa_sd"]) * 1e6, rel=1e-12)
        assert v.dLf_D == float(rec["dLf_D_mean"])
        assert v.sigma_c == pytest.approx(float(fits[key]["sigma_c_mpa"]) * 1e6, rel=1e-12)
        assert v.rrmse == float(fits[key]["rrmse"])


@pytest.mark.parametrize("args, words", [
    (("ash", 8, 60), ["material", "'birch'", "'oak'", "'pine'"]),
    (("oak", 12, 60), ["mc", "[8, 20]"]),
    (("oak", 0.08, 60), ["mc", "fraction"]),
    (("oak", 8, 90), ["sigma_z", "[60, 120]"]),
    (("oak", 8, 60e6), ["sigma_z", "looks like Pa"]),
    (("oak", "eight", 60), ["mc"]),
    ((None, 8, 60), ["material"]),
])
def test_variant_rejects_bad_arguments(args, words):
    with pytest.raises(ValueError) as err:
        m.variant(*args)
    for w in words:
        assert w in str(err.value)


# --------------------------------------------------------------------------------------
# User curves: good files
# --------------------------------------------------------------------------------------

D_MM, H_MM = 10.0, 6.4


def test_form_a_mpa_with_replicates(tmp_path):
    f = _write(tmp_path / "a.csv", "replicate,dL_D,sigma_1_mpa\n"
               "p1,0.0,0.0\np1,0.02,0.5\np1,0.05,1.3\n"
               "p2,0.0,0.0\np2,0.03,0.6\np2,0.06,1.2\n")
    c = m.load_curve(f)
    assert c.kind == "diametral"
    assert c.replicates == ("p1", "p2")
    np.testing.assert_array_equal(c.x, [0.0, 0.02, 0.05, 0.0, 0.03, 0.06])
    np.testing.assert_allclose(c.y, [0.0, 0.5e6, 1.3e6, 0.0, 0.6e6, 1.2e6], rtol=1e-15)
    assert c.source == str(f)


def test_form_a_pa_without_replicate_column(tmp_path):
    f = _write(tmp_path / "a.csv", "dL_D,sigma_1_pa\n0,0\n0.01,2.0e5\n0.02,3.0e5\n")
    c = m.load_curve(f, replicate="pelletA")
    assert c.replicates == ("pelletA",)
    np.testing.assert_array_equal(c.y, [0.0, 2.0e5, 3.0e5])


def test_form_b_eq4_conversion_by_hand(tmp_path):
    f = _write(tmp_path / "machine.csv", "time_s,displacement_mm,force_n\n"
               "0,0,0\n6,0.2,50\n15,0.5,100\n24,0.8,80\n")
    c = m.load_curve(f, diameter=D_MM * 1e-3, height=H_MM * 1e-3)
    # sigma_1 = P / (pi R h): 100 N / (pi * 0.005 m * 0.0064 m) = 994718.39 Pa
    assert c.y[2] == pytest.approx(994718.39, rel=1e-8)
    assert c.y[1] == pytest.approx(994718.39 / 2, rel=1e-8)
    np.testing.assert_allclose(c.x, [0.0, 0.02, 0.05, 0.08], rtol=1e-12)
    assert c.metadata["diameter_m"] == pytest.approx(0.010)
    assert c.metadata["height_m"] == pytest.approx(0.0064)


def test_form_b_header_dimensions_and_crosshead_offset(tmp_path):
    # An absolute crosshead position: dL is measured from the first row.
    f = _write(tmp_path / "machine.csv", "# Lloyd LRX export\n# diameter_mm=10.0, height_mm=6.4\n"
               "time_s;displacement_mm;force_n\n0;12.0;0\n15;12.5;100\n24;12.8;80\n")
    c = m.load_curve(f)
    np.testing.assert_allclose(c.x, [0.0, 0.05, 0.08], atol=1e-12)
    assert c.y[1] == pytest.approx(994718.39, rel=1e-8)
    assert "diameter_mm" not in c.metadata  # replaced by the SI key


def test_form_b_arguments_override_header_and_metres_column(tmp_path):
    f = _write(tmp_path / "machine.csv", "# diameter_mm=99, height_mm=99\n"
               "displacement_m,force_n\n0,0\n0.0005,100\n0.0008,80\n")
    c = m.load_curve(f, diameter=0.010, height=0.0064)
    assert c.x[1] == pytest.approx(0.05)
    assert c.y[1] == pytest.approx(994718.39, rel=1e-8)


def test_compaction_curve(tmp_path):
    f = _write(tmp_path / "comp.csv", "dh_h0,sigma_z_mpa\n0,0\n0.5,2\n0.7,40\n0.75,120\n")
    c = m.load_curve(f, kind="compaction")
    assert c.kind == "compaction"
    assert c.y[-1] == pytest.approx(120e6)
    with pytest.raises(ValueError, match="diametral"):
        c.peak()


def test_bad_kind_rejected(tmp_path):
    f = _write(tmp_path / "a.csv", "dL_D,sigma_1_mpa\n0,0\n0.1,1\n0.2,2\n")
    with pytest.raises(ValueError, match="kind must be one of"):
        m.load_curve(f, kind="tension")


# --------------------------------------------------------------------------------------
# Round trip
# --------------------------------------------------------------------------------------


def test_round_trip_is_exact(tmp_path):
    src = _write(tmp_path / "machine.csv", "# diameter_mm=10.02, height_mm=6.41, operator=AB\n"
                 "time_s,displacement_mm,force_n,replicate\n"
                 "0,0,0,1\n1,0.1,33.3,1\n2,0.3,77.7,1\n0,0,0,2\n1,0.2,40.1,2\n2,0.4,70.9,2\n")
    first = m.load_curve(src)
    m.save_curve(first, tmp_path / "saved.csv")
    second = m.load_curve(tmp_path / "saved.csv")
    assert second == first
    assert second.metadata == {"operator": "AB", "diameter_m": 0.01002, "height_m": 0.00641}
    m.save_curve(second, tmp_path / "saved2.csv")
    assert (tmp_path / "saved2.csv").read_text() == (tmp_path / "saved.csv").read_text()


def test_curve_equality_detects_a_changed_value(tmp_path):
    c = m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5])
    assert c == m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5])
    assert c != m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5 + 1e-9])
    assert c != m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5], replicate=["2"] * 3)


def test_compaction_round_trip(tmp_path):
    c = m.Curve([0.1, 0.5, 0.75], [1e5, 2e6, 1.2e8], kind="compaction", metadata={"mould_d_m": 0.01})
    m.save_curve(c, tmp_path / "c.csv")
    assert m.load_curve(tmp_path / "c.csv", kind="compaction") == c
    with pytest.raises(m.MeasuredDataError, match="kind=compaction"):
        m.load_curve(tmp_path / "c.csv", kind="diametral")


def test_save_rejects_unsaveable_metadata(tmp_path):
    c = m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5], metadata={"note": "a, b"})
    with pytest.raises(ValueError, match="note"):
        m.save_curve(c, tmp_path / "x.csv")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_round_trip_property(tmp_path, data):
    n = data.draw(st.integers(3, 30))
    x = sorted(data.draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    y = data.draw(st.lists(st.floats(1.0e3, 1.0e9), min_size=n, max_size=n))
    c = m.Curve(x, y, replicate=["r1"] * n)
    m.save_curve(c, tmp_path / "p.csv")
    back = m.load_curve(tmp_path / "p.csv")
    np.testing.assert_array_equal(back.x, c.x)
    np.testing.assert_array_equal(back.y, c.y)
    assert back == c


# --------------------------------------------------------------------------------------
# Mean curve and peak
# --------------------------------------------------------------------------------------


def _two_linear_replicates():
    # y = 1e6 x and y = 3e6 x on different x samplings
    x1 = np.array([0.0, 0.04, 0.1])
    x2 = np.array([0.0, 0.02, 0.05, 0.08])
    return m.Curve(np.r_[x1, x2], np.r_[1e6 * x1, 3e6 * x2], replicate=["a"] * 3 + ["b"] * 4)


def test_mean_curve_by_hand():
    mc = _two_linear_replicates().mean_curve([0.05, 0.09])
    # at 0.05: replicates give 5e4 and 1.5e5 -> mean 1e5, sample SD 1e5 / sqrt(2)
    assert mc.mean[0] == pytest.approx(1.0e5)
    assert mc.sd[0] == pytest.approx(1.0e5 / math.sqrt(2))
    assert mc.n[0] == 2
    # 0.09 is past replicate b's last point: only replicate a counts, SD undefined
    assert mc.n[1] == 1 and mc.mean[1] == pytest.approx(9e4) and math.isnan(mc.sd[1])


def test_mean_curve_default_grid_is_common_range():
    mc = _two_linear_replicates().mean_curve()
    assert mc.x[0] == 0.0 and mc.x[-1] == pytest.approx(0.08) and len(mc.x) == 101
    assert (mc.n == 2).all()


def test_peak_per_replicate_and_statistics():
    c = m.Curve([0.0, 0.05, 0.07, 0.0, 0.06, 0.08],
                [0.0, 1.3e6, 1.1e6, 0.0, 1.2e6, 1.4e6], replicate=list("aaabbb"))
    p = c.peak()
    assert p.replicate == ("a", "b")
    np.testing.assert_array_equal(p.sigma_f, [1.3e6, 1.4e6])
    np.testing.assert_array_equal(p.dLf_D, [0.05, 0.08])
    assert p.sigma_f_mean == pytest.approx(1.35e6)
    assert p.sigma_f_sd == pytest.approx(0.1e6 / math.sqrt(2))
    assert p.dLf_D_mean == pytest.approx(0.065)
    assert p.dLf_D_sd == pytest.approx(0.03 / math.sqrt(2))


def test_concat_curves_and_duplicate_ids(tmp_path):
    a = m.Curve([0.0, 0.1, 0.2], [0.0, 1e5, 2e5], replicate=["1"] * 3)
    b = m.Curve([0.0, 0.1, 0.2], [0.0, 2e5, 3e5], replicate=["2"] * 3)
    both = m.concat_curves([a, b])
    assert both.replicates == ("1", "2") and len(both) == 6
    with pytest.raises(ValueError, match="repeat"):
        m.concat_curves([a, a])


# --------------------------------------------------------------------------------------
# Malformed files: every message names file, data row and column
# --------------------------------------------------------------------------------------

MACHINE = "time_s,displacement_mm,force_n\n"


def _expect(tmp_path, text, row, column, *words, **kwargs):
    f = _write(tmp_path / "bad.csv", text)
    with pytest.raises(m.MeasuredDataError) as err:
        m.load_curve(f, **kwargs)
    msg = str(err.value)
    assert "bad.csv" in msg
    assert err.value.row == row and err.value.column == column
    if row is not None:
        assert f"data row {row} (1-based" in msg
    if column is not None:
        assert f"column '{column}'" in msg
    for w in words:
        assert w in msg, msg
    return err.value


def test_missing_columns_lists_found_and_required(tmp_path):
    _expect(tmp_path, "dL_D,stress\n0,0\n0.1,1\n0.2,2\n", None, None,
            "found ['dL_D', 'stress']", "sigma_1_mpa", "displacement_mm", "force_n")


def test_missing_columns_compaction(tmp_path):
    _expect(tmp_path, "dh,sigma_z_mpa\n0,0\n0.1,1\n0.2,2\n", None, None, "dh_h0", kind="compaction")


def test_non_numeric_cell(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n0.01,0.4\n0.02,abc\n0.03,0.9\n", 3, "sigma_1_mpa", "'abc'")


def test_empty_cell(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n0.01,\n0.02,0.7\n", 2, "sigma_1_mpa", "empty")


@pytest.mark.parametrize("token", ["nan", "inf", "-inf"])
def test_nan_and_inf(tmp_path, token):
    _expect(tmp_path, f"dL_D,sigma_1_mpa\n0,0\n{token},0.4\n0.02,0.7\n", 2, "dL_D", "NaN or infinite")


def test_wrong_cell_count(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n0.01,0.4,9\n0.02,0.7\n", 2, None, "3 cells")


def test_row_numbers_skip_comment_lines_and_give_file_line(tmp_path):
    err = _expect(tmp_path, "# one\n# two\ndL_D,sigma_1_mpa\n0,0\nx,0.4\n0.02,0.7\n", 2, "dL_D", "line 5")
    assert err.line == 5


def test_negative_force(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,0.1,20\n2,0.2,-5\n3,0.3,30\n", 3, "force_n", "negative",
            diameter=0.01, height=0.0064)


def test_force_noise_near_zero_is_tolerated(tmp_path):
    f = _write(tmp_path / "ok.csv", MACHINE + "0,0,-0.02\n1,0.1,20\n2,0.2,40\n")
    assert len(m.load_curve(f, diameter=0.01, height=0.0064)) == 3


def test_negative_diameter_argument(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,0.1,20\n2,0.2,40\n", None, None, "argument diameter", "positive",
            diameter=-0.01, height=0.0064)


def test_negative_height_in_header(tmp_path):
    _expect(tmp_path, "# diameter_mm=10, height_mm=-6.4\n" + MACHINE + "0,0,0\n1,0.1,20\n2,0.2,40\n",
            None, None, "height_mm=-6.4", "positive")


def test_missing_diameter(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,0.1,20\n2,0.2,40\n", None, None, "diameter", "diameter_mm",
            height=0.0064)


def test_diameter_in_mm_passed_as_metres(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,0.1,20\n2,0.2,40\n", None, None, "looks like millimetres",
            diameter=10.0, height=0.0064)


def test_sigma_mpa_column_holding_pa(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n0.03,673000\n0.06,1346000\n", 2, "sigma_1_mpa", "looks like Pa")


def test_sigma_pa_column_holding_mpa(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_pa\n0,0\n0.03,0.67\n0.06,1.35\n", 3, "sigma_1_pa", "looks like MPa")


def test_dl_d_in_percent(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n3,0.6\n6,1.3\n", 2, "dL_D", "percent")


def test_displacement_in_micrometres_exceeds_diameter(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,200,20\n2,500,40\n", 2, "displacement_mm", "diameter",
            diameter=0.01, height=0.0064)


def test_displacement_not_monotonic_names_first_offending_row(tmp_path):
    _expect(tmp_path, MACHINE + "0,0,0\n1,0.2,20\n2,0.1,25\n3,0.05,30\n4,0.3,40\n", 3, "displacement_mm",
            "decreases", "data row 2", diameter=0.01, height=0.0064)


def test_monotonic_is_checked_within_each_replicate(tmp_path):
    # the restart at replicate 2 is fine; the decrease inside replicate 2 is not
    _expect(tmp_path, "replicate,dL_D,sigma_1_mpa\n1,0,0\n1,0.05,1\n1,0.08,0.9\n"
            "2,0,0\n2,0.04,0.8\n2,0.03,0.9\n2,0.06,1\n", 6, "dL_D", "replicate '2'")


def test_too_few_points(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n0,0\n0.01,0.4\n", 1, "dL_D", "at least 3")


def test_too_few_points_in_one_replicate(tmp_path):
    _expect(tmp_path, "replicate,dL_D,sigma_1_mpa\na,0,0\na,0.01,0.4\na,0.02,0.5\nb,0,0\nb,0.01,0.3\n",
            4, "replicate", "'b'", "at least 3")


def test_header_only(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa\n", None, "dL_D", "at least 3")


def test_empty_file(tmp_path):
    _expect(tmp_path, "# only a comment\n", None, None, "no header")


def test_both_stress_units_given(tmp_path):
    _expect(tmp_path, "dL_D,sigma_1_mpa,sigma_1_pa\n0,0,0\n0.1,1,1e6\n0.2,2,2e6\n", None, None, "give one")


def test_missing_file(tmp_path):
    with pytest.raises(m.MeasuredDataError, match="nope.csv"):
        m.load_curve(tmp_path / "nope.csv")


def test_measured_data_error_is_a_value_error():
    assert issubclass(m.MeasuredDataError, ValueError)
