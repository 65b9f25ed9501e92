// A world's whole state as a dict of numpy arrays and back (checkpoints, and runs branched
// across processes), every field checked before a state is loaded.
#include <cmath>
#include <limits>

#include "bindings.hpp"

namespace pelletdem::bindings {

namespace {

template <class T>
std::vector<T> from_array(const py::dict& d, const char* key) {
  if (!d.contains(key)) throw ParameterError(cat("state: missing '", key, "'"));
  auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(d[key]);
  if (!a) throw ParameterError(cat("state: '", key, "' is not a numeric array"));
  return std::vector<T>(a.data(), a.data() + a.size());
}

std::vector<Vec3> vec3_from(const py::dict& d, const char* key) {
  auto flat = from_array<double>(d, key);
  if (flat.size() % 3 != 0) throw ParameterError(cat("state: '", key, "' must have shape (N, 3)"));
  std::vector<Vec3> out(flat.size() / 3);
  for (std::size_t k = 0; k < out.size(); ++k) out[k] = Vec3(flat[3 * k], flat[3 * k + 1], flat[3 * k + 2]);
  return out;
}

py::dict wall_to_dict(const Wall& w) {
  py::dict d;
  d["name"] = w.name;
  d["kind"] = w.kind == WallKind::Plane ? "plane" : "cylinder";
  d["point"] = copy_vec3({w.point});
  d["normal"] = copy_vec3({w.normal});
  d["velocity"] = copy_vec3({w.velocity});
  d["radius"] = w.radius;
  d["radius_rate"] = w.radius_rate;
  d["active"] = w.active;
  d["servo"] = w.servo;
  d["servo_force"] = w.servo_force;
  d["servo_gain"] = w.servo_gain;
  d["servo_max_speed"] = w.servo_max_speed;
  d["travel"] = w.travel;
  d["moved_since_build"] = w.moved_since_build;
  // The last force evaluation's results: a stage reads them before its first step (the
  // unloading stage takes the piston's peak load from them), so a restored world needs them.
  d["force"] = copy_vec3({w.force});
  d["torque"] = copy_vec3({w.torque});
  d["radial_force"] = w.radial_force;
  d["max_overlap_ratio"] = w.max_overlap_ratio;
  d["max_overlap_particle"] = static_cast<long>(w.max_overlap_particle);
  d["crushable"] = w.crushable;
  std::vector<Index> ci;
  std::vector<double> d0;
  std::vector<Vec3> ft;
  for (const WallContact& c : w.contacts) {
    ci.push_back(c.i);
    d0.push_back(c.h.delta0);
    ft.push_back(c.h.ft);
  }
  d["contact_i"] = copy_vector(ci);
  d["contact_delta0"] = copy_vector(d0);
  d["contact_ft"] = copy_vec3(ft);
  return d;
}

Wall wall_from_dict(const py::dict& d) {
  Wall w;
  w.name = d["name"].cast<std::string>();
  const std::string kind = d["kind"].cast<std::string>();
  if (kind != "plane" && kind != "cylinder")
    throw ParameterError("state: wall kind must be plane or cylinder");
  w.kind = kind == "plane" ? WallKind::Plane : WallKind::Cylinder;
  w.point = vec3_from(d, "point").at(0);
  w.normal = vec3_from(d, "normal").at(0);
  w.velocity = vec3_from(d, "velocity").at(0);
  w.radius = d["radius"].cast<double>();
  w.radius_rate = d["radius_rate"].cast<double>();
  w.active = d["active"].cast<bool>();
  w.servo = d["servo"].cast<bool>();
  w.servo_force = d["servo_force"].cast<double>();
  w.servo_gain = d["servo_gain"].cast<double>();
  w.servo_max_speed = d["servo_max_speed"].cast<double>();
  w.travel = d["travel"].cast<double>();
  w.moved_since_build = d["moved_since_build"].cast<double>();
  if (d.contains("force")) {  // older checkpoints lack them: zero until the next step
    w.force = vec3_from(d, "force").at(0);
    w.torque = vec3_from(d, "torque").at(0);
    w.radial_force = d["radial_force"].cast<double>();
    w.max_overlap_ratio = d["max_overlap_ratio"].cast<double>();
    const long who = d["max_overlap_particle"].cast<long>();
    if (who < 0) throw ParameterError("state: wall max_overlap_particle must be >= 0");
    w.max_overlap_particle = static_cast<Index>(who);
  }
  w.crushable = d.contains("crushable") ? d["crushable"].cast<bool>() : false;  // older checkpoints
  auto ci = from_array<Index>(d, "contact_i");
  auto d0 = from_array<double>(d, "contact_delta0");
  auto ft = vec3_from(d, "contact_ft");
  if (ci.size() != d0.size() || ci.size() != ft.size())
    throw ParameterError("state: wall contact arrays differ in length");
  for (std::size_t k = 0; k < ci.size(); ++k)
    w.contacts.push_back(WallContact{ci[k], ContactHistory{d0[k], ft[k]}});
  return w;
}

// The broken-bond record as arrays (time s, step, pair, bond centre m, mode 1 tension / 2 shear,
// stresses Pa at breakage, load marker m).
}  // namespace

py::dict broken_to_dict(const std::vector<BrokenBond>& b) {
  const std::size_t n = b.size();
  std::vector<double> t(n), sig(n), tau(n), lm(n);
  std::vector<long> step(n);
  std::vector<Index> i(n), j(n);
  std::vector<std::uint8_t> mode(n);
  std::vector<Vec3> pos(n);
  for (std::size_t k = 0; k < n; ++k) {
    t[k] = b[k].time;
    step[k] = b[k].step;
    i[k] = b[k].i;
    j[k] = b[k].j;
    pos[k] = b[k].position;
    mode[k] = static_cast<std::uint8_t>(b[k].mode);
    sig[k] = b[k].sigma;
    tau[k] = b[k].tau;
    lm[k] = b[k].load_marker;
  }
  py::dict d;
  d["time"] = copy_vector(t);
  d["step"] = copy_vector(step);
  d["i"] = copy_vector(i);
  d["j"] = copy_vector(j);
  d["position"] = copy_vec3(pos);
  d["mode"] = copy_vector(mode);
  d["sigma"] = copy_vector(sig);
  d["tau"] = copy_vector(tau);
  d["load_marker"] = copy_vector(lm);
  return d;
}

py::dict state_to_dict(const WorldState& s) {
  py::dict d;
  d["time"] = s.time;
  d["step"] = s.step;
  d["ramp_start"] = s.ramp_start;
  d["ramp_duration"] = s.ramp_duration;
  d["max_overlap_seen"] = s.max_overlap_seen;
  d["forces_valid"] = s.forces_valid;
  d["load_peak_from"] = s.load_peak_from;
  d["load_peak"] = s.load_peak;
  d["load_smoothing"] = s.load_smoothing;
  d["load_smoothed"] = s.load_smoothed;
  d["x"] = copy_vec3(s.x);
  d["v"] = copy_vec3(s.v);
  d["w"] = copy_vec3(s.w);
  d["f"] = copy_vec3(s.f);
  d["t"] = copy_vec3(s.t);
  d["r"] = copy_vector(s.r);
  d["m"] = copy_vector(s.m);
  if (!s.x_build.empty()) d["x_build"] = copy_vec3(s.x_build);
  d["contact_i"] = copy_vector(s.ci);
  d["contact_j"] = copy_vector(s.cj);
  d["contact_delta0"] = copy_vector(s.c_delta0);
  d["contact_ft"] = copy_vec3(s.c_ft);
  py::list walls;
  for (const Wall& w : s.walls) walls.append(wall_to_dict(w));
  d["walls"] = walls;
  d["load_walls"] = copy_vector(s.load_walls);
  const std::size_t nb = s.bonds.size();
  std::vector<Index> bi(nb), bj(nb);
  std::vector<std::uint8_t> mode(nb);
  std::vector<double> fn(nb), mn(nb), rad(nb), kn(nb), kt(nb), sc(nb), tc(nb), soft(nb), dmg(nb);
  std::vector<Vec3> np_(nb), ft(nb), mt(nb);
  for (std::size_t k = 0; k < nb; ++k) {
    const Bond& b = s.bonds[k];
    bi[k] = b.i;
    bj[k] = b.j;
    mode[k] = static_cast<std::uint8_t>(b.mode);
    fn[k] = b.fn;
    mn[k] = b.mn;
    rad[k] = b.radius;
    kn[k] = b.kn;
    kt[k] = b.kt;
    sc[k] = b.sigma_c;
    tc[k] = b.tau_c;
    soft[k] = b.softening;
    dmg[k] = b.damage;
    np_[k] = b.n_prev;
    ft[k] = b.ft;
    mt[k] = b.mt;
  }
  d["bond_i"] = copy_vector(bi);
  d["bond_j"] = copy_vector(bj);
  d["bond_mode"] = copy_vector(mode);
  d["bond_fn"] = copy_vector(fn);
  d["bond_mn"] = copy_vector(mn);
  d["bond_radius"] = copy_vector(rad);
  d["bond_kn"] = copy_vector(kn);
  d["bond_kt"] = copy_vector(kt);
  d["bond_sigma_c"] = copy_vector(sc);
  d["bond_softening"] = copy_vector(soft);
  d["bond_damage"] = copy_vector(dmg);
  d["bond_tau_c"] = copy_vector(tc);
  d["bond_n_prev"] = copy_vec3(np_);
  d["bond_ft"] = copy_vec3(ft);
  d["bond_mt"] = copy_vec3(mt);
  for (auto item : broken_to_dict(s.broken))
    d[py::str("broken_" + item.first.cast<std::string>())] = item.second;
  return d;
}

WorldState state_from_dict(const py::dict& d) {
  WorldState s;
  s.time = d["time"].cast<double>();
  s.step = d["step"].cast<long>();
  s.ramp_start = d["ramp_start"].cast<double>();
  s.ramp_duration = d["ramp_duration"].cast<double>();
  s.max_overlap_seen = d["max_overlap_seen"].cast<double>();
  s.forces_valid = d["forces_valid"].cast<bool>();
  // The tracked load peak arrived after checkpoint format 1: older files tracked none.
  if (d.contains("load_peak_from")) s.load_peak_from = d["load_peak_from"].cast<double>();
  if (d.contains("load_peak")) s.load_peak = d["load_peak"].cast<double>();
  if (d.contains("load_smoothing")) s.load_smoothing = d["load_smoothing"].cast<double>();
  if (d.contains("load_smoothed")) s.load_smoothed = d["load_smoothed"].cast<double>();
  s.x = vec3_from(d, "x");
  s.v = vec3_from(d, "v");
  s.w = vec3_from(d, "w");
  s.f = vec3_from(d, "f");
  s.t = vec3_from(d, "t");
  s.r = from_array<double>(d, "r");
  s.m = from_array<double>(d, "m");
  // Positions of the last list build: optional (older files have none).
  if (d.contains("x_build")) s.x_build = vec3_from(d, "x_build");
  s.ci = from_array<Index>(d, "contact_i");
  s.cj = from_array<Index>(d, "contact_j");
  s.c_delta0 = from_array<double>(d, "contact_delta0");
  s.c_ft = vec3_from(d, "contact_ft");
  for (auto item : d["walls"].cast<py::list>()) s.walls.push_back(wall_from_dict(item.cast<py::dict>()));
  s.load_walls = from_array<int>(d, "load_walls");
  auto bi = from_array<Index>(d, "bond_i"), bj = from_array<Index>(d, "bond_j");
  auto mode = from_array<std::uint8_t>(d, "bond_mode");
  auto fn = from_array<double>(d, "bond_fn"), mn = from_array<double>(d, "bond_mn"),
       rad = from_array<double>(d, "bond_radius");
  auto kn = from_array<double>(d, "bond_kn"), kt = from_array<double>(d, "bond_kt");
  auto sc = from_array<double>(d, "bond_sigma_c"), tc = from_array<double>(d, "bond_tau_c");
  auto np_ = vec3_from(d, "bond_n_prev"), ft = vec3_from(d, "bond_ft"), mt = vec3_from(d, "bond_mt");
  const std::size_t nb = bi.size();
  // Softening arrived with checkpoint format 1 still current: older files have brittle bonds.
  std::vector<double> soft(nb, 0.0), dmg(nb, 0.0);
  if (d.contains("bond_softening")) soft = from_array<double>(d, "bond_softening");
  if (d.contains("bond_damage")) dmg = from_array<double>(d, "bond_damage");
  if (soft.size() != nb || dmg.size() != nb) throw ParameterError("state: bond arrays differ in length");
  for (auto* v : {&bj})
    if (v->size() != nb) throw ParameterError("state: bond arrays differ in length");
  if (mode.size() != nb || fn.size() != nb || mn.size() != nb || rad.size() != nb || kn.size() != nb ||
      kt.size() != nb || sc.size() != nb || tc.size() != nb || np_.size() != nb || ft.size() != nb ||
      mt.size() != nb)
    throw ParameterError("state: bond arrays differ in length");
  for (std::size_t k = 0; k < nb; ++k) {
    if (mode[k] > 2) throw ParameterError("state: bond mode must be 0, 1 or 2");
    Bond b;
    b.i = bi[k];
    b.j = bj[k];
    b.mode = static_cast<BondMode>(mode[k]);
    b.fn = fn[k];
    b.mn = mn[k];
    b.radius = rad[k];
    b.kn = kn[k];
    b.kt = kt[k];
    b.sigma_c = sc[k];
    b.tau_c = tc[k];
    b.n_prev = np_[k];
    b.ft = ft[k];
    b.mt = mt[k];
    if (!(dmg[k] >= 0.0 && dmg[k] < 1.0) || !(soft[k] >= 0.0))
      throw ParameterError(cat("state: bond ", k, " has damage ", dmg[k],
                               " (allowed 0 <= damage < 1) or softening ", soft[k], " (allowed >= 0)"));
    b.softening = soft[k];
    b.damage = dmg[k];
    s.bonds.push_back(b);
  }
  auto kt_ = from_array<double>(d, "broken_time");
  auto kstep = from_array<long>(d, "broken_step");
  auto ki = from_array<Index>(d, "broken_i"), kj = from_array<Index>(d, "broken_j");
  auto kpos = vec3_from(d, "broken_position");
  auto kmode = from_array<std::uint8_t>(d, "broken_mode");
  auto ks = from_array<double>(d, "broken_sigma"), ktau = from_array<double>(d, "broken_tau"),
       klm = from_array<double>(d, "broken_load_marker");
  const std::size_t nk = kt_.size();
  if (kstep.size() != nk || ki.size() != nk || kj.size() != nk || kpos.size() != nk || kmode.size() != nk ||
      ks.size() != nk || ktau.size() != nk || klm.size() != nk)
    throw ParameterError("state: broken-bond arrays differ in length");
  for (std::size_t k = 0; k < nk; ++k)
    s.broken.push_back(BrokenBond{kt_[k], kstep[k], ki[k], kj[k], kpos[k], static_cast<BondMode>(kmode[k]),
                                  ks[k], ktau[k], klm[k]});
  return s;
}

void set_world_state(World& w, const py::object& obj) {
  if (!py::isinstance<py::dict>(obj))
    throw ParameterError(cat("state must be a dict from get_state(), got ",
                             py::str(py::type::of(obj).attr("__name__")).cast<std::string>()));
  WorldState s;
  // A missing key, a value of the wrong type or an empty array is a broken state
  // dict: say so as a ParameterError, not a KeyError or IndexError from deep inside.
  try {
    s = state_from_dict(obj.cast<py::dict>());
  } catch (const ParameterError&) {
    throw;
  } catch (const py::error_already_set& e) {
    throw ParameterError(cat("state: malformed (", e.what(), ")"));
  } catch (const py::cast_error& e) {
    throw ParameterError(cat("state: a value has the wrong type (", e.what(), ")"));
  } catch (const std::out_of_range& e) {
    throw ParameterError(cat("state: an array is empty or too short (", e.what(), ")"));
  }
  if (!std::isfinite(s.time) || s.step < 0 || !std::isfinite(s.ramp_start) ||
      !std::isfinite(s.ramp_duration) || !std::isfinite(s.max_overlap_seen))
    throw ParameterError(cat("state: time = ", s.time, " s, step = ", s.step,
                             ", ramp and max_overlap_seen must be finite (step >= 0)"));
  if (std::isnan(s.load_peak_from) || !std::isfinite(s.load_peak) || s.load_peak < 0.0 ||
      !(s.load_smoothing >= 1.0 && s.load_smoothing <= 1e9) || std::isnan(s.load_smoothed) ||
      s.load_smoothed == std::numeric_limits<double>::infinity())
    throw ParameterError(cat("state: load_peak = ", s.load_peak, " N must be finite and >= 0, ",
                             "load_peak_from = ", s.load_peak_from, " m must not be NaN, ",
                             "load_smoothing = ", s.load_smoothing, " steps must be in [1, 1e9], ",
                             "load_smoothed = ", s.load_smoothed, " N must be finite (-inf: none yet)"));
  // What load_state does not check itself, checked before it changes anything (it
  // checks load walls only after taking the new walls, which would leave half a state).
  for (int k : s.load_walls)
    if (k < 0 || k >= static_cast<int>(s.walls.size()))
      throw ParameterError(cat("state: load wall index ", k, " out of range 0..", s.walls.size() - 1));
  const std::size_t n = s.r.size();
  if (s.x.size() != n || s.v.size() != n || s.w.size() != n || s.f.size() != n || s.t.size() != n ||
      s.m.size() != n)
    throw ParameterError("state: particle arrays x, v, w, f, t, r, m must all have the same length");
  if (s.ci.size() != s.cj.size() || s.ci.size() != s.c_delta0.size() || s.ci.size() != s.c_ft.size())
    throw ParameterError("state: contact arrays must all have the same length");
  for (std::size_t k = 0; k < n; ++k)
    if (!std::isfinite(s.r[k]) || !std::isfinite(s.m[k]) || !s.w[k].allFinite() || !s.f[k].allFinite() ||
        !s.t[k].allFinite())
      throw ParameterError(
          cat("state: particle ", k, " has a non-finite radius, mass, spin, force or torque"));
  for (std::size_t k = 0; k < s.c_ft.size(); ++k)
    if (!std::isfinite(s.c_delta0[k]) || !s.c_ft[k].allFinite())
      throw ParameterError(cat("state: contact ", k, " has a non-finite history"));
  for (std::size_t k = 0; k < s.bonds.size(); ++k) {
    const Bond& b = s.bonds[k];
    const bool ok = b.i != b.j && b.radius > 0.0 && std::isfinite(b.radius) && b.kn >= 0.0 &&
                    std::isfinite(b.kn) && b.kt >= 0.0 && std::isfinite(b.kt) && b.sigma_c > 0.0 &&
                    std::isfinite(b.sigma_c) && b.tau_c > 0.0 && std::isfinite(b.tau_c) &&
                    std::isfinite(b.fn) && std::isfinite(b.mn) && b.ft.allFinite() && b.mt.allFinite() &&
                    b.n_prev.allFinite();
    if (!ok)
      throw ParameterError(cat("state: bond ", k, " (", b.i, ", ", b.j,
                               ") joins a particle to itself or has "
                               "a non-finite or non-positive radius, stiffness, strength or load"));
  }
  w.load_state(s);
}

}  // namespace pelletdem::bindings
