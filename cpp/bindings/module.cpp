// The only C++ that knows Python. Long runs release the GIL and go in chunks of ~0.1 s so that
// Ctrl-C and progress callbacks are served between chunks, never inside the step loop.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace py = pybind11;
using namespace pelletdem;

namespace {

using Arr = py::array_t<double, py::array::c_style | py::array::forcecast>;

Vec3 to_vec3(const std::vector<double>& v, const char* name) {
  if (v.size() != 3) throw ParameterError(cat(name, " must have 3 components, got ", v.size()));
  return Vec3(v[0], v[1], v[2]);
}

// numpy's view of obj, refused unless its dtype is real (float or integer): forcecast alone
// would turn complex numbers into their real parts and None into NaN without a word.
py::array real_array(const py::handle& obj, const char* name, const char* shape) {
  py::array raw;
  try {
    raw = py::module_::import("numpy").attr("asarray")(obj);
  } catch (py::error_already_set&) {
    throw ParameterError(cat(name, " must be a numeric array of shape ", shape));
  }
  const char kind = raw.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u')
    throw ParameterError(cat(name, " must be a real numeric array (float or int) of shape ", shape,
                             ", got dtype ", py::str(raw.dtype()).cast<std::string>()));
  return raw;
}

std::string shape_of(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t k = 0; k < a.ndim(); ++k) s += (k ? ", " : "") + std::to_string(a.shape(k));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

std::vector<Vec3> to_vec3_array(const py::handle& obj, const char* name) {
  Arr a = Arr::ensure(real_array(obj, name, "(N, 3)"));
  if (!a) throw ParameterError(cat(name, " must be a numeric array of shape (N, 3)"));
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw ParameterError(cat(name, " must have shape (N, 3), got shape ", shape_of(a)));
  std::vector<Vec3> out(a.shape(0));
  auto r = a.unchecked<2>();
  for (py::ssize_t k = 0; k < a.shape(0); ++k) out[k] = Vec3(r(k, 0), r(k, 1), r(k, 2));
  return out;
}

std::vector<double> to_vector(const py::handle& obj, const char* name) {
  Arr a = Arr::ensure(real_array(obj, name, "(N,)"));
  if (!a) throw ParameterError(cat(name, " must be a numeric array of shape (N,)"));
  if (a.ndim() != 1)
    throw ParameterError(cat(name, " must be one-dimensional, shape (N,), got shape ", shape_of(a)));
  return std::vector<double>(a.data(), a.data() + a.shape(0));
}

py::array_t<double> copy_vec3(const std::vector<Vec3>& v) {
  py::array_t<double> a({static_cast<py::ssize_t>(v.size()), static_cast<py::ssize_t>(3)});
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(Vec3));
  return a;
}

template <class T>
py::array_t<T> copy_vector(const std::vector<T>& v) {
  py::array_t<T> a(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(T));
  return a;
}

struct ViewHolder {
  std::shared_ptr<int> counter;
  py::object owner;
};

// A read-only numpy view of a particle array. While it lives the world refuses to add
// particles (which would move the memory under it).
template <class T>
py::array view_of(World& w, const T* data, std::size_t n, std::size_t width, py::object owner) {
  auto counter = w.view_counter();
  ++*counter;
  py::capsule base(new ViewHolder{counter, owner}, [](void* p) {
    auto* h = static_cast<ViewHolder*>(p);
    --*h->counter;
    delete h;
  });
  py::array out;
  const py::ssize_t N = static_cast<py::ssize_t>(n);
  if (width == 1) {
    out = py::array_t<double>({N}, {static_cast<py::ssize_t>(sizeof(double))},
                              reinterpret_cast<const double*>(data), base);
  } else {
    out = py::array_t<double>({N, static_cast<py::ssize_t>(3)},
                              {static_cast<py::ssize_t>(sizeof(Vec3)),
                               static_cast<py::ssize_t>(sizeof(double))},
                              reinterpret_cast<const double*>(data), base);
  }
  out.attr("flags").attr("writeable") = false;
  return out;
}

// Runs the engine in chunks with the GIL released; returns (condition index, steps run).
// `between(done)` is called only when the run goes on after a chunk: the world then sits
// between two steps and no stop condition has fired, so a checkpoint taken there resumes
// exactly (one taken after the chunk that met a condition would run past it on resume).
py::tuple run_chunked(World& w, std::vector<StopCondition> conds, long max_steps,
                      const py::object& progress, const py::object& between) {
  if (max_steps < 0) throw ParameterError(cat("max_steps = ", max_steps, " must be >= 0"));
  // "Steps" counts over the whole call, so it becomes the budget rather than a per-chunk test.
  std::vector<int> index_map;
  std::vector<StopCondition> inner;
  long steps_limit = max_steps;
  int steps_index = -1;
  for (std::size_t k = 0; k < conds.size(); ++k) {
    if (conds[k].kind == StopKind::Steps) {
      if (!(conds[k].value >= 0)) throw ParameterError("stop condition steps must be >= 0");
      if (conds[k].value <= static_cast<double>(steps_limit)) {  // compared as doubles: 1e300 must not overflow a long
        steps_limit = static_cast<long>(conds[k].value);
        steps_index = static_cast<int>(k);
      }
    } else {
      inner.push_back(conds[k]);
      index_map.push_back(static_cast<int>(k));
    }
  }
  // The first chunk is sized by the particle count (~2e5 particle-steps, tens of ms), so
  // even a 40,000-particle world answers Ctrl-C well within a second from the start.
  const long n_particles = static_cast<long>(w.particles().size());
  long done = 0, chunk = std::clamp(200000L / std::max(n_particles, 1L), 1L, 200L);
  while (true) {
    const long this_chunk = std::min(chunk, steps_limit - done);
    RunOutcome r;
    double seconds = 0.0;
    if (this_chunk > 0) {
      py::gil_scoped_release release;
      const auto t0 = std::chrono::steady_clock::now();
      r = w.run_until(inner, this_chunk);
      seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    done += r.steps;
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    if (!progress.is_none()) progress(done);
    if (r.condition >= 0) return py::make_tuple(index_map[r.condition], done);
    if (done >= steps_limit) return py::make_tuple(done >= max_steps && steps_index < 0 ? -1 : steps_index, done);
    if (!between.is_none()) between(done);
    // Aim for ~0.1 s per chunk so an interrupt is served well within a second.
    if (seconds > 0.0) chunk = std::clamp(static_cast<long>(this_chunk * 0.1 / seconds), 1L, 1000000L);
    else chunk = std::min(chunk * 4, 1000000L);
  }
}

// --- state <-> dict of numpy arrays (checkpoints, branching runs across processes) ---------
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
  for (const WallContact& c : w.contacts) { ci.push_back(c.i); d0.push_back(c.h.delta0); ft.push_back(c.h.ft); }
  d["contact_i"] = copy_vector(ci);
  d["contact_delta0"] = copy_vector(d0);
  d["contact_ft"] = copy_vec3(ft);
  return d;
}

Wall wall_from_dict(const py::dict& d) {
  Wall w;
  w.name = d["name"].cast<std::string>();
  const std::string kind = d["kind"].cast<std::string>();
  if (kind != "plane" && kind != "cylinder") throw ParameterError("state: wall kind must be plane or cylinder");
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
  if (ci.size() != d0.size() || ci.size() != ft.size()) throw ParameterError("state: wall contact arrays differ in length");
  for (std::size_t k = 0; k < ci.size(); ++k) w.contacts.push_back(WallContact{ci[k], ContactHistory{d0[k], ft[k]}});
  return w;
}

// The broken-bond record as arrays (time s, step, pair, bond centre m, mode 1 tension / 2 shear,
// stresses Pa at breakage, load marker m).
py::dict broken_to_dict(const std::vector<BrokenBond>& b) {
  const std::size_t n = b.size();
  std::vector<double> t(n), sig(n), tau(n), lm(n);
  std::vector<long> step(n);
  std::vector<Index> i(n), j(n);
  std::vector<std::uint8_t> mode(n);
  std::vector<Vec3> pos(n);
  for (std::size_t k = 0; k < n; ++k) {
    t[k] = b[k].time; step[k] = b[k].step; i[k] = b[k].i; j[k] = b[k].j; pos[k] = b[k].position;
    mode[k] = static_cast<std::uint8_t>(b[k].mode); sig[k] = b[k].sigma; tau[k] = b[k].tau; lm[k] = b[k].load_marker;
  }
  py::dict d;
  d["time"] = copy_vector(t); d["step"] = copy_vector(step); d["i"] = copy_vector(i); d["j"] = copy_vector(j);
  d["position"] = copy_vec3(pos); d["mode"] = copy_vector(mode); d["sigma"] = copy_vector(sig);
  d["tau"] = copy_vector(tau); d["load_marker"] = copy_vector(lm);
  return d;
}

py::dict state_to_dict(const WorldState& s) {
  py::dict d;
  d["time"] = s.time; d["step"] = s.step; d["ramp_start"] = s.ramp_start; d["ramp_duration"] = s.ramp_duration;
  d["max_overlap_seen"] = s.max_overlap_seen; d["forces_valid"] = s.forces_valid;
  d["load_peak_from"] = s.load_peak_from; d["load_peak"] = s.load_peak;
  d["load_smoothing"] = s.load_smoothing; d["load_smoothed"] = s.load_smoothed;
  d["x"] = copy_vec3(s.x); d["v"] = copy_vec3(s.v); d["w"] = copy_vec3(s.w); d["f"] = copy_vec3(s.f); d["t"] = copy_vec3(s.t);
  d["r"] = copy_vector(s.r); d["m"] = copy_vector(s.m);
  if (!s.x_build.empty()) d["x_build"] = copy_vec3(s.x_build);
  d["contact_i"] = copy_vector(s.ci); d["contact_j"] = copy_vector(s.cj);
  d["contact_delta0"] = copy_vector(s.c_delta0); d["contact_ft"] = copy_vec3(s.c_ft);
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
    bi[k] = b.i; bj[k] = b.j; mode[k] = static_cast<std::uint8_t>(b.mode); fn[k] = b.fn; mn[k] = b.mn;
    rad[k] = b.radius; kn[k] = b.kn; kt[k] = b.kt; sc[k] = b.sigma_c; tc[k] = b.tau_c;
    soft[k] = b.softening; dmg[k] = b.damage;
    np_[k] = b.n_prev; ft[k] = b.ft; mt[k] = b.mt;
  }
  d["bond_i"] = copy_vector(bi); d["bond_j"] = copy_vector(bj); d["bond_mode"] = copy_vector(mode);
  d["bond_fn"] = copy_vector(fn); d["bond_mn"] = copy_vector(mn); d["bond_radius"] = copy_vector(rad);
  d["bond_kn"] = copy_vector(kn); d["bond_kt"] = copy_vector(kt); d["bond_sigma_c"] = copy_vector(sc);
  d["bond_softening"] = copy_vector(soft); d["bond_damage"] = copy_vector(dmg);
  d["bond_tau_c"] = copy_vector(tc); d["bond_n_prev"] = copy_vec3(np_); d["bond_ft"] = copy_vec3(ft); d["bond_mt"] = copy_vec3(mt);
  for (auto item : broken_to_dict(s.broken)) d[py::str("broken_" + item.first.cast<std::string>())] = item.second;
  return d;
}

WorldState state_from_dict(const py::dict& d) {
  WorldState s;
  s.time = d["time"].cast<double>(); s.step = d["step"].cast<long>();
  s.ramp_start = d["ramp_start"].cast<double>(); s.ramp_duration = d["ramp_duration"].cast<double>();
  s.max_overlap_seen = d["max_overlap_seen"].cast<double>(); s.forces_valid = d["forces_valid"].cast<bool>();
  // The tracked load peak arrived after checkpoint format 1: older files tracked none.
  if (d.contains("load_peak_from")) s.load_peak_from = d["load_peak_from"].cast<double>();
  if (d.contains("load_peak")) s.load_peak = d["load_peak"].cast<double>();
  if (d.contains("load_smoothing")) s.load_smoothing = d["load_smoothing"].cast<double>();
  if (d.contains("load_smoothed")) s.load_smoothed = d["load_smoothed"].cast<double>();
  s.x = vec3_from(d, "x"); s.v = vec3_from(d, "v"); s.w = vec3_from(d, "w"); s.f = vec3_from(d, "f"); s.t = vec3_from(d, "t");
  s.r = from_array<double>(d, "r"); s.m = from_array<double>(d, "m");
  // Positions of the last list build: optional (older files have none).
  if (d.contains("x_build")) s.x_build = vec3_from(d, "x_build");
  s.ci = from_array<Index>(d, "contact_i"); s.cj = from_array<Index>(d, "contact_j");
  s.c_delta0 = from_array<double>(d, "contact_delta0"); s.c_ft = vec3_from(d, "contact_ft");
  for (auto item : d["walls"].cast<py::list>()) s.walls.push_back(wall_from_dict(item.cast<py::dict>()));
  s.load_walls = from_array<int>(d, "load_walls");
  auto bi = from_array<Index>(d, "bond_i"), bj = from_array<Index>(d, "bond_j");
  auto mode = from_array<std::uint8_t>(d, "bond_mode");
  auto fn = from_array<double>(d, "bond_fn"), mn = from_array<double>(d, "bond_mn"), rad = from_array<double>(d, "bond_radius");
  auto kn = from_array<double>(d, "bond_kn"), kt = from_array<double>(d, "bond_kt");
  auto sc = from_array<double>(d, "bond_sigma_c"), tc = from_array<double>(d, "bond_tau_c");
  auto np_ = vec3_from(d, "bond_n_prev"), ft = vec3_from(d, "bond_ft"), mt = vec3_from(d, "bond_mt");
  const std::size_t nb = bi.size();
  // Softening arrived with checkpoint format 1 still current: older files have brittle bonds.
  std::vector<double> soft(nb, 0.0), dmg(nb, 0.0);
  if (d.contains("bond_softening")) soft = from_array<double>(d, "bond_softening");
  if (d.contains("bond_damage")) dmg = from_array<double>(d, "bond_damage");
  if (soft.size() != nb || dmg.size() != nb) throw ParameterError("state: bond arrays differ in length");
  for (auto* v : {&bj}) if (v->size() != nb) throw ParameterError("state: bond arrays differ in length");
  if (mode.size() != nb || fn.size() != nb || mn.size() != nb || rad.size() != nb || kn.size() != nb || kt.size() != nb ||
      sc.size() != nb || tc.size() != nb || np_.size() != nb || ft.size() != nb || mt.size() != nb)
    throw ParameterError("state: bond arrays differ in length");
  for (std::size_t k = 0; k < nb; ++k) {
    if (mode[k] > 2) throw ParameterError("state: bond mode must be 0, 1 or 2");
    Bond b;
    b.i = bi[k]; b.j = bj[k]; b.mode = static_cast<BondMode>(mode[k]); b.fn = fn[k]; b.mn = mn[k];
    b.radius = rad[k]; b.kn = kn[k]; b.kt = kt[k]; b.sigma_c = sc[k]; b.tau_c = tc[k];
    b.n_prev = np_[k]; b.ft = ft[k]; b.mt = mt[k];
    if (!(dmg[k] >= 0.0 && dmg[k] < 1.0) || !(soft[k] >= 0.0))
      throw ParameterError(cat("state: bond ", k, " has damage ", dmg[k], " (allowed 0 <= damage < 1) or softening ", soft[k], " (allowed >= 0)"));
    b.softening = soft[k]; b.damage = dmg[k];
    s.bonds.push_back(b);
  }
  auto kt_ = from_array<double>(d, "broken_time");
  auto kstep = from_array<long>(d, "broken_step");
  auto ki = from_array<Index>(d, "broken_i"), kj = from_array<Index>(d, "broken_j");
  auto kpos = vec3_from(d, "broken_position");
  auto kmode = from_array<std::uint8_t>(d, "broken_mode");
  auto ks = from_array<double>(d, "broken_sigma"), ktau = from_array<double>(d, "broken_tau"), klm = from_array<double>(d, "broken_load_marker");
  const std::size_t nk = kt_.size();
  if (kstep.size() != nk || ki.size() != nk || kj.size() != nk || kpos.size() != nk || kmode.size() != nk ||
      ks.size() != nk || ktau.size() != nk || klm.size() != nk)
    throw ParameterError("state: broken-bond arrays differ in length");
  for (std::size_t k = 0; k < nk; ++k)
    s.broken.push_back(BrokenBond{kt_[k], kstep[k], ki[k], kj[k], kpos[k], static_cast<BondMode>(kmode[k]), ks[k], ktau[k], klm[k]});
  return s;
}

// Radii are drawn by rejection, so a range holding almost none of the distribution (sd huge,
// infinite, or the range far in a tail) would loop for ever; refuse it before drawing. The
// count is capped so that a huge n is an error, not an 8n-byte allocation.
constexpr double kMaxRadii = 1e7;
constexpr double kMinAcceptance = 1e-3;

std::vector<double> checked_truncated_normal_radii(long n, double mean, double sd, double r_min,
                                                   double r_max, std::uint64_t seed) {
  require_range("n", static_cast<double>(n), 0, kMaxRadii, "particles");
  if (std::isfinite(mean) && std::isfinite(r_min) && std::isfinite(r_max) && sd > 0.0 &&
      r_max >= r_min) {
    // Fraction of N(mean, sd) inside [r_min, r_max]; 0 for an infinite sd.
    const double s = std::isfinite(sd) ? sd * std::sqrt(2.0) : HUGE_VAL;
    const double p = 0.5 * (std::erfc((mean - r_max) / s) - std::erfc((mean - r_min) / s));
    if (!(p >= kMinAcceptance))
      throw ParameterError(cat("radius range [r_min, r_max] = [", r_min, ", ", r_max,
                               "] m holds a fraction ", p, " of the normal distribution (mean ",
                               mean, " m, sd ", sd, " m): allowed >= ", kMinAcceptance,
                               " (narrow sd or widen the range)"));
  }
  return truncated_normal_radii(n, mean, sd, r_min, r_max, seed);
}

// The placement grid indexes cells of 2 r_max with ints and hashes them into a 64-bit key:
// coordinates must be finite and within a million cells of the origin, and the region must
// be tall enough for the largest sphere (else it is placed outside it).
void check_pack_region(const std::vector<double>& r, double cx, double cy, double radius,
                       double z_lo, double z_hi) {
  require(std::isfinite(cx) && std::isfinite(cy), cat("fill centre (", cx, ", ", cy, ") m must be finite"));
  require(std::isfinite(z_lo) && std::isfinite(z_hi),
          cat("fill region z_lo = ", z_lo, " m, z_hi = ", z_hi, " m must be finite"));
  require_positive("fill radius", radius, "m");
  double r_max = 0.0;
  for (double q : r)
    if (q > 0.0 && std::isfinite(q)) r_max = std::max(r_max, q);
  if (r_max <= 0.0) return;  // no valid radius: the engine names the bad one
  const double reach = std::max({std::abs(cx) + radius, std::abs(cy) + radius, std::abs(z_lo), std::abs(z_hi)});
  if (!(reach / (2.0 * r_max) < 1e6))
    throw ParameterError(cat("fill region reaches ", reach, " m from the origin, more than 1e6 particle "
                             "diameters (2 r_max = ", 2.0 * r_max, " m): allowed |coordinate| < ",
                             2e6 * r_max, " m"));
  require(!(z_hi > z_lo) || z_hi - z_lo >= 2.0 * r_max,  // (a reversed range: the engine says so)
          cat("fill region height z_hi - z_lo = ", z_hi - z_lo, " m must be >= the largest diameter ",
              2.0 * r_max, " m"));
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "pelletdem's C++ engine: DEM with the linear hysteretic adhesive contact law and "
            "parallel bonds. Use the Python layer (pelletdem) rather than this module directly.";

  auto param_err = py::register_exception<ParameterError>(m, "ParameterError", PyExc_ValueError);
  auto sim_err = py::register_exception<SimulationError>(m, "SimulationError", PyExc_RuntimeError);
  py::register_exception<ParticleEscapedError>(m, "ParticleEscapedError", sim_err.ptr());
  py::register_exception<OverlapError>(m, "OverlapError", sim_err.ptr());
  py::register_exception<NonFiniteError>(m, "NonFiniteError", sim_err.ptr());
  (void)param_err;

  py::class_<ContactLawParams>(m, "ContactLawParams")
      .def(py::init<>())
      .def_readwrite("k1", &ContactLawParams::k1)
      .def_readwrite("k2", &ContactLawParams::k2)
      .def_readwrite("kc", &ContactLawParams::kc)
      .def_readwrite("kt_ratio", &ContactLawParams::kt_ratio)
      .def_readwrite("mu", &ContactLawParams::mu)
      .def_readwrite("mu_wall", &ContactLawParams::mu_wall)
      .def_readwrite("rolling", &ContactLawParams::rolling)
      .def_readwrite("wall_adhesion", &ContactLawParams::wall_adhesion)
      .def_readwrite("wall_stiffness_factor", &ContactLawParams::wall_stiffness_factor)
      .def_readwrite("normal_damping_ratio", &ContactLawParams::normal_damping_ratio)
      .def_readwrite("scale_with_radius", &ContactLawParams::scale_with_radius)
      .def_readwrite("r_ref", &ContactLawParams::r_ref)
      .def_readwrite("hardening", &ContactLawParams::hardening)
      .def_readwrite("hardening_exponent", &ContactLawParams::hardening_exponent)
      .def_readwrite("unloading_growth", &ContactLawParams::unloading_growth)
      .def_readwrite("plate_yield_stress", &ContactLawParams::plate_yield_stress)
      .def("restitution", &ContactLawParams::restitution)
      .def("validate", &ContactLawParams::validate);

  py::class_<BondParams>(m, "BondParams")
      .def(py::init<>())
      .def_readwrite("radius", &BondParams::radius)
      .def_readwrite("youngs_modulus", &BondParams::youngs_modulus)
      .def_readwrite("kt_ratio", &BondParams::kt_ratio)
      .def_readwrite("sigma_c", &BondParams::sigma_c)
      .def_readwrite("tau_c", &BondParams::tau_c)
      .def_readwrite("gap_tolerance", &BondParams::gap_tolerance)
      .def_readwrite("weibull_modulus", &BondParams::weibull_modulus)
      .def_readwrite("strength_seed", &BondParams::strength_seed)
      .def_readwrite("softening", &BondParams::softening)
      .def_readwrite("overlap_radius_gain", &BondParams::overlap_radius_gain)
      .def_readwrite("moisture_content", &BondParams::moisture_content)
      .def_readwrite("moisture_reference", &BondParams::moisture_reference)
      .def_readwrite("moisture_coefficient", &BondParams::moisture_coefficient)
      .def("validate", &BondParams::validate);

  py::class_<WorldParams>(m, "WorldParams")
      .def(py::init<>())
      .def_readwrite("dt", &WorldParams::dt)
      .def_property("gravity", [](const WorldParams& p) { return std::vector<double>{p.gravity.x(), p.gravity.y(), p.gravity.z()}; },
                    [](WorldParams& p, const std::vector<double>& g) { p.gravity = to_vec3(g, "gravity"); })
      .def_readwrite("density", &WorldParams::density)
      .def_readwrite("density_scale", &WorldParams::density_scale)
      .def_readwrite("skin", &WorldParams::skin)
      .def_property("box_lo", [](const WorldParams& p) { return std::vector<double>{p.box.lo.x(), p.box.lo.y(), p.box.lo.z()}; },
                    [](WorldParams& p, const std::vector<double>& g) { p.box.lo = to_vec3(g, "box_lo"); })
      .def_property("box_hi", [](const WorldParams& p) { return std::vector<double>{p.box.hi.x(), p.box.hi.y(), p.box.hi.z()}; },
                    [](WorldParams& p, const std::vector<double>& g) { p.box.hi = to_vec3(g, "box_hi"); })
      .def_readwrite("threads", &WorldParams::threads)
      .def_readwrite("max_overlap_ratio", &WorldParams::max_overlap_ratio)
      .def_readwrite("sample_interval", &WorldParams::sample_interval)
      .def_readwrite("contact", &WorldParams::contact);

  py::enum_<StopKind>(m, "StopKind")
      .value("Time", StopKind::Time)
      .value("Steps", StopKind::Steps)
      .value("KineticEnergyBelow", StopKind::KineticEnergyBelow)
      .value("InternalKineticEnergyBelow", StopKind::InternalKineticEnergyBelow)
      .value("WallForceAbove", StopKind::WallForceAbove)
      .value("WallForceBelow", StopKind::WallForceBelow)
      .value("WallTravelAbove", StopKind::WallTravelAbove)
      .value("LoadMarkerAbove", StopKind::LoadMarkerAbove)
      .value("LoadDropBelow", StopKind::LoadDropBelow);

  py::class_<StopCondition>(m, "StopCondition")
      .def(py::init([](StopKind kind, double value, int wall, long check_interval) {
             return StopCondition{kind, value, wall, check_interval};
           }),
           py::arg("kind"), py::arg("value"), py::arg("wall") = -1, py::arg("check_interval") = 1)
      .def_readonly("kind", &StopCondition::kind)
      .def_readonly("value", &StopCondition::value)
      .def_readonly("wall", &StopCondition::wall)
      .def_readonly("check_interval", &StopCondition::check_interval);

  py::class_<World>(m, "World")
      .def(py::init<const WorldParams&>(), py::arg("params"))
      .def("clone", &World::clone)
      .def("sort_particles", [](World& w) { return copy_vector(w.sort_particles()); },
           "Renumber the particles in Morton order of their neighbour cells; returns the old "
           "index of each new particle.")
      .def("get_state", [](const World& w) { return state_to_dict(w.save_state()); },
           "The whole state as a dict of numpy arrays (see pelletdem.checkpoint).")
      .def("set_state",
           [](World& w, const py::object& obj) {
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
             if (s.x.size() != n || s.v.size() != n || s.w.size() != n || s.f.size() != n ||
                 s.t.size() != n || s.m.size() != n)
               throw ParameterError("state: particle arrays x, v, w, f, t, r, m must all have the same length");
             if (s.ci.size() != s.cj.size() || s.ci.size() != s.c_delta0.size() || s.ci.size() != s.c_ft.size())
               throw ParameterError("state: contact arrays must all have the same length");
             for (std::size_t k = 0; k < n; ++k)
               if (!std::isfinite(s.r[k]) || !std::isfinite(s.m[k]) || !s.w[k].allFinite() ||
                   !s.f[k].allFinite() || !s.t[k].allFinite())
                 throw ParameterError(cat("state: particle ", k, " has a non-finite radius, mass, spin, force or torque"));
             for (std::size_t k = 0; k < s.c_ft.size(); ++k)
               if (!std::isfinite(s.c_delta0[k]) || !s.c_ft[k].allFinite())
                 throw ParameterError(cat("state: contact ", k, " has a non-finite history"));
             for (std::size_t k = 0; k < s.bonds.size(); ++k) {
               const Bond& b = s.bonds[k];
               const bool ok = b.i != b.j && b.radius > 0.0 && std::isfinite(b.radius) && b.kn >= 0.0 &&
                               std::isfinite(b.kn) && b.kt >= 0.0 && std::isfinite(b.kt) && b.sigma_c > 0.0 &&
                               std::isfinite(b.sigma_c) && b.tau_c > 0.0 && std::isfinite(b.tau_c) &&
                               std::isfinite(b.fn) && std::isfinite(b.mn) && b.ft.allFinite() &&
                               b.mt.allFinite() && b.n_prev.allFinite();
               if (!ok)
                 throw ParameterError(cat("state: bond ", k, " (", b.i, ", ", b.j, ") joins a particle to itself or has "
                                          "a non-finite or non-positive radius, stiffness, strength or load"));
             }
             w.load_state(s);
           },
           "Restore a state from get_state() into a world built with the same parameters.")
      .def("add_particles",
           [](World& w, const py::object& x, const py::object& r) {
             w.add_particles(to_vec3_array(x, "positions"), to_vector(r, "radii"));
           },
           py::arg("positions"), py::arg("radii"))
      .def("add_plane",
           [](World& w, const std::string& name, const std::vector<double>& point,
              const std::vector<double>& normal) {
             return w.add_plane(name, to_vec3(point, "point"), to_vec3(normal, "normal"));
           },
           py::arg("name"), py::arg("point"), py::arg("normal"))
      .def("add_cylinder",
           [](World& w, const std::string& name, const std::vector<double>& axis_point, double radius) {
             return w.add_cylinder(name, to_vec3(axis_point, "axis_point"), radius);
           },
           py::arg("name"), py::arg("axis_point"), py::arg("radius"))
      .def_property_readonly("wall_count", &World::wall_count)
      .def("wall_name", [](const World& w, int k) { return w.wall(k).name; })
      .def("wall_kind", [](const World& w, int k) { return w.wall(k).kind == WallKind::Plane ? "plane" : "cylinder"; })
      .def("set_wall_velocity",
           [](World& w, int k, const std::vector<double>& v) {
             Vec3 vv = to_vec3(v, "velocity");
             if (!vv.allFinite()) throw ParameterError("wall velocity must be finite (m/s)");
             w.wall(k).velocity = vv;
             w.wall(k).servo = false;
           })
      .def("set_wall_radius_rate",
           [](World& w, int k, double rate) {
             if (!std::isfinite(rate)) throw ParameterError("radius_rate must be finite (m/s)");
             if (w.wall(k).kind != WallKind::Cylinder) throw ParameterError("radius_rate applies to cylinders only");
             w.wall(k).radius_rate = rate;
           })
      .def("set_wall_servo",
           [](World& w, int k, double force, double gain, double max_speed) {
             Wall& wl = w.wall(k);
             if (wl.kind != WallKind::Plane) throw ParameterError("a servo drives planes only");
             wl.servo = true;
             wl.servo_force = force;
             wl.servo_gain = gain;
             wl.servo_max_speed = max_speed;
             try { wl.validate(); } catch (...) { wl.servo = false; throw; }
           })
      .def("set_wall_active", [](World& w, int k, bool a) { w.wall(k).active = a; w.invalidate(); })
      .def("set_wall_crushable", [](World& w, int k, bool c) { w.wall(k).crushable = c; w.invalidate(); },
           "Contacts with wall k obey the contact law's plate_yield_stress (crushing under the plates).")
      .def("set_wall_point",
           [](World& w, int k, const std::vector<double>& p) {
             const Vec3 q = to_vec3(p, "point");
             if (!q.allFinite()) throw ParameterError("wall point must be finite (m)");
             w.wall(k).point = q;
             w.invalidate();
           })
      .def("set_wall_radius",
           [](World& w, int k, double r) {
             require_positive("cylinder radius", r, "m");
             w.wall(k).radius = r;
             w.invalidate();
           })
      .def("wall_state",
           [](const World& w, int k) {
             const Wall& wl = w.wall(k);
             py::dict d;
             d["name"] = wl.name;
             d["kind"] = wl.kind == WallKind::Plane ? "plane" : "cylinder";
             d["point"] = std::vector<double>{wl.point.x(), wl.point.y(), wl.point.z()};
             d["normal"] = std::vector<double>{wl.normal.x(), wl.normal.y(), wl.normal.z()};
             d["radius"] = wl.radius;
             d["velocity"] = std::vector<double>{wl.velocity.x(), wl.velocity.y(), wl.velocity.z()};
             d["radius_rate"] = wl.radius_rate;
             d["force"] = std::vector<double>{wl.force.x(), wl.force.y(), wl.force.z()};
             d["torque"] = std::vector<double>{wl.torque.x(), wl.torque.y(), wl.torque.z()};
             d["normal_force"] = wl.normal_force();
             d["travel"] = wl.travel;
             d["active"] = wl.active;
             d["max_overlap_ratio"] = wl.max_overlap_ratio;
             d["contacts"] = wl.contacts.size();
             return d;
           })
      .def("set_contact_params", &World::set_contact_params)
      .def_property_readonly("contact_params", [](const World& w) { return w.params().contact; })
      .def_property("dt", [](const World& w) { return w.params().dt; }, &World::set_dt)
      .def_property("threads", [](const World& w) { return w.params().threads; }, &World::set_threads)
      .def_property("gravity",
                    [](const World& w) { const Vec3& g = w.params().gravity; return std::vector<double>{g.x(), g.y(), g.z()}; },
                    [](World& w, const std::vector<double>& g) { w.set_gravity(to_vec3(g, "gravity")); })
      .def_property_readonly("density_scale", [](const World& w) { return w.params().density_scale; })
      .def_property_readonly("density", [](const World& w) { return w.params().density; })
      .def("set_load_walls", &World::set_load_walls)
      .def("set_adhesion_ramp", &World::set_adhesion_ramp, py::arg("t_start"), py::arg("duration"))
      .def_property_readonly("adhesion_scale", &World::adhesion_scale)
      .def("set_max_overlap_ratio", &World::set_max_overlap_ratio)
      .def("set_sample_interval", &World::set_sample_interval)
      .def("run_until", &run_chunked, py::arg("conditions"), py::arg("max_steps"),
           py::arg("progress") = py::none(), py::arg("between") = py::none())
      .def_property_readonly("sample_interval", [](const World& w) { return w.params().sample_interval; },
                             "Steps between time-series samples.")
      .def_property_readonly("max_overlap_ratio", [](const World& w) { return w.params().max_overlap_ratio; },
                             "The overlap guard: delta / r beyond it stops a run.")
      .def("step", [](World& w) { py::gil_scoped_release r; w.step(); })
      .def_property_readonly("time", &World::time)
      .def_property_readonly("step_count", &World::step_count)
      .def_property("vector_kernels", &World::vector_kernels, &World::set_vector_kernels,
                    "Four-lane pair and bond kernels (default on); off runs the scalar ones, "
                    "which give the same bits (the tests check it).")
      .def_property_readonly("n", [](const World& w) { return w.particles().size(); })
      .def("kinetic_energy", [](const World& w) { return w.kinetic_energy(); })
      .def("potential_energy", [](const World& w) { return w.potential_energy(); })
      .def("internal_kinetic_energy", &World::internal_kinetic_energy,
           "Kinetic energy in the centre-of-mass frame, J (scaled mass).")
      .def("mean_velocity", [](const World& w) { Vec3 v = w.mean_velocity(); return std::vector<double>{v.x(), v.y(), v.z()}; })
      .def("remove_mean_velocity", [](World& w) { w.remove_mean_velocity(); })
      .def("coordination_number", &World::coordination_number)
      .def_property_readonly("contact_count", &World::contact_count)
      .def_property_readonly("max_overlap_ratio_seen", &World::max_overlap_ratio_seen)
      .def("reset_max_overlap_seen", &World::reset_max_overlap_seen)
      .def_property_readonly("load_marker", &World::load_marker)
      .def_property_readonly("load_force", &World::load_force,
                             "Mean compressive normal force of the load walls, N.")
      .def_property_readonly("load_peak", &World::load_peak,
                             "Largest load_smoothed since track_load_peak's marker was reached, N.")
      .def_property_readonly("load_smoothed", &World::load_smoothed,
                             "load_force averaged over track_load_peak's smoothing_steps, N.")
      .def("track_load_peak", &World::track_load_peak, py::arg("from_marker"), py::arg("smoothing_steps") = 1.0,
           "Average the load force over ~smoothing_steps steps and keep its peak from the load marker "
           "from_marker (m) on, for the load_drop_below stop (inf: stop keeping them).")
      .def("critical_time_step", &World::critical_time_step)
      .def_property_readonly("rebuild_count", &World::rebuild_count)
      .def_property_readonly("pair_list_size", [](const World& w) { return w.neighbors().pair_count(); })
      // Read-only zero-copy views.
      .def_property_readonly("x", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().x.data(), w.particles().size(), 3, self); })
      .def_property_readonly("v", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().v.data(), w.particles().size(), 3, self); })
      .def_property_readonly("w", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().w.data(), w.particles().size(), 3, self); })
      .def_property_readonly("f", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().f.data(), w.particles().size(), 3, self); })
      .def_property_readonly("t", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().t.data(), w.particles().size(), 3, self); })
      .def_property_readonly("r", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().r.data(), w.particles().size(), 1, self); })
      .def_property_readonly("m", [](py::object self) { World& w = self.cast<World&>(); return view_of(w, w.particles().m.data(), w.particles().size(), 1, self); })
      .def("set_velocities",
           [](World& w, const py::object& v, const py::object& omega) {
             auto vv = to_vec3_array(v, "velocities");
             auto ww = to_vec3_array(omega, "angular velocities");
             auto& p = w.particles();
             if (vv.size() != p.size() || ww.size() != p.size())
               throw ParameterError(cat("velocities must have shape (", p.size(), ", 3)"));
             for (auto& x : vv) if (!x.allFinite()) throw ParameterError("velocities must be finite");
             for (auto& x : ww) if (!x.allFinite()) throw ParameterError("angular velocities must be finite");
             p.v = vv;
             p.w = ww;
             w.invalidate();
           })
      .def("set_positions",
           [](World& w, const py::object& x) {
             auto xx = to_vec3_array(x, "positions");
             auto& p = w.particles();
             if (xx.size() != p.size()) throw ParameterError(cat("positions must have shape (", p.size(), ", 3)"));
             for (auto& q : xx) if (!q.allFinite()) throw ParameterError("positions must be finite");
             p.x = xx;
             w.invalidate();
           })
      .def("contacts",
           [](const World& w) {
             std::vector<Index> i, j;
             std::vector<double> ov, fn;
             w.contacts(i, j, ov, fn);
             py::dict d;
             d["i"] = copy_vector(i);
             d["j"] = copy_vector(j);
             d["overlap"] = copy_vector(ov);
             d["fn"] = copy_vector(fn);
             return d;
           })
      .def("samples",
           [](const World& w) {
             const auto& s = w.samples();
             const std::size_t n = s.size();
             std::vector<double> t(n), ke(n), cn(n), ov(n), lm(n), nc(n), nbi(n), nbb(n);
             for (std::size_t k = 0; k < n; ++k) {
               t[k] = s[k].time; ke[k] = s[k].kinetic_energy; cn[k] = s[k].coordination_number;
               ov[k] = s[k].max_overlap_ratio; lm[k] = s[k].load_marker; nc[k] = s[k].n_contacts;
               nbi[k] = s[k].n_bonds_intact; nbb[k] = s[k].n_bonds_broken;
             }
             py::dict d;
             d["time"] = copy_vector(t);
             d["kinetic_energy"] = copy_vector(ke);
             d["coordination_number"] = copy_vector(cn);
             d["max_overlap_ratio"] = copy_vector(ov);
             d["load_marker"] = copy_vector(lm);
             d["n_contacts"] = copy_vector(nc);
             d["n_bonds_intact"] = copy_vector(nbi);
             d["n_bonds_broken"] = copy_vector(nbb);
             return d;
           })
      .def("wall_samples",
           [](const World& w, int k) {
             if (k < 0 || k >= w.wall_count()) throw ParameterError(cat("wall index ", k, " out of range 0..", w.wall_count() - 1));
             const auto& s = w.wall_samples(k);
             const std::size_t n = s.size();
             std::vector<double> t(n), fn(n), rad(n), tr(n);
             std::vector<Vec3> f(n), pt(n);
             for (std::size_t q = 0; q < n; ++q) {
               t[q] = s[q].time; fn[q] = s[q].normal_force; rad[q] = s[q].radius; tr[q] = s[q].travel;
               f[q] = s[q].force; pt[q] = s[q].point;
             }
             py::dict d;
             d["time"] = copy_vector(t);
             d["force"] = copy_vec3(f);
             d["normal_force"] = copy_vector(fn);
             d["point"] = copy_vec3(pt);
             d["radius"] = copy_vector(rad);
             d["travel"] = copy_vector(tr);
             return d;
           })
      .def("clear_samples", &World::clear_samples)
      .def("record_sample", &World::record_sample)
      .def("create_bonds", [](World& w, const BondParams& p) { py::gil_scoped_release r; return w.create_bonds(p); })
      .def_property_readonly("bond_count", [](const World& w) { return w.bonds().size(); })
      .def("intact_bond_count", &World::intact_bond_count)
      .def("bonds",
           [](const World& w) {
             const auto& b = w.bonds();
             const std::size_t n = b.size();
             std::vector<Index> i(n), j(n);
             std::vector<std::uint8_t> mode(n);
             std::vector<double> fn(n), mn(n), rad(n), kn(n), kt(n), sc(n), tc(n), sig(n), tau(n), dmg(n);
             std::vector<Vec3> ft(n), mt(n);
             for (std::size_t k = 0; k < n; ++k) {
               i[k] = b[k].i; j[k] = b[k].j; mode[k] = static_cast<std::uint8_t>(b[k].mode);
               fn[k] = b[k].fn; mn[k] = b[k].mn; ft[k] = b[k].ft; mt[k] = b[k].mt;
               rad[k] = b[k].radius; kn[k] = b[k].kn; kt[k] = b[k].kt; sc[k] = b[k].sigma_c; tc[k] = b[k].tau_c;
               sig[k] = b[k].sigma_max(); tau[k] = b[k].tau_max(); dmg[k] = b[k].damage;
             }
             py::dict d;
             d["i"] = copy_vector(i); d["j"] = copy_vector(j); d["mode"] = copy_vector(mode);
             d["fn"] = copy_vector(fn); d["ft"] = copy_vec3(ft); d["mn"] = copy_vector(mn); d["mt"] = copy_vec3(mt);
             d["radius"] = copy_vector(rad); d["kn"] = copy_vector(kn); d["kt"] = copy_vector(kt);
             d["sigma_c"] = copy_vector(sc); d["tau_c"] = copy_vector(tc); d["damage"] = copy_vector(dmg);
             d["sigma_max"] = copy_vector(sig); d["tau_max"] = copy_vector(tau);
             return d;
           })
      .def("set_bond_property",
           [](World& w, const std::string& name, const py::object& values) {
             auto v = to_vector(values, name.c_str());
             auto& b = w.bonds_mut();
             if (v.size() != b.size()) throw ParameterError(cat(name, " must have one value per bond (", b.size(), "), got ", v.size()));
             for (std::size_t k = 0; k < v.size(); ++k)
               if (!(v[k] > 0.0) || !std::isfinite(v[k]))
                 throw ParameterError(cat(name, "[", k, "] = ", v[k], " must be finite and > 0"));
             double Bond::*field = nullptr;
             if (name == "radius") field = &Bond::radius;
             else if (name == "kn") field = &Bond::kn;
             else if (name == "kt") field = &Bond::kt;
             else if (name == "sigma_c") field = &Bond::sigma_c;
             else if (name == "tau_c") field = &Bond::tau_c;
             else throw ParameterError(cat("unknown bond property '", name, "': allowed radius, kn, kt, sigma_c, tau_c"));
             for (std::size_t k = 0; k < v.size(); ++k) b[k].*field = v[k];
           })
      .def("broken_bonds", [](const World& w) { return broken_to_dict(w.broken_bonds()); });

  m.def("truncated_normal_radii", &checked_truncated_normal_radii, py::arg("n"), py::arg("mean"), py::arg("sd"),
        py::arg("r_min"), py::arg("r_max"), py::arg("seed"),
        "Radii (m) from a normal distribution truncated to [r_min, r_max], seeded.");
  m.def("random_pack_cylinder",
        [](const py::object& radii, double cx, double cy, double radius, double z_lo, double z_hi,
           std::uint64_t seed, long max_attempts) {
          std::vector<double> r = to_vector(radii, "radii");
          check_pack_region(r, cx, cy, radius, z_lo, z_hi);
          std::vector<Vec3> x;
          {
            py::gil_scoped_release rel;
            x = random_pack_cylinder(r, cx, cy, radius, z_lo, z_hi, seed, max_attempts);
          }
          return py::make_tuple(copy_vec3(x), copy_vector(r));
        },
        py::arg("radii"), py::arg("cx"), py::arg("cy"), py::arg("radius"), py::arg("z_lo"), py::arg("z_hi"),
        py::arg("seed"), py::arg("max_attempts") = 100000,
        "Random non-overlapping placement in a z-aligned cylinder; returns (positions, radii) sorted along z.");
  m.def("brute_force_pairs",
        [](const py::object& x, const py::object& r, double skin) {
          Particles p;
          auto xx = to_vec3_array(x, "positions");
          auto rr = to_vector(r, "radii");
          if (xx.size() != rr.size()) throw ParameterError("positions and radii must have the same length");
          for (std::size_t k = 0; k < xx.size(); ++k) p.push(xx[k], rr[k], 1.0);
          auto pairs = NeighborList::brute_force(p, skin);
          std::vector<Index> i, j;
          for (auto& q : pairs) { i.push_back(q.first); j.push_back(q.second); }
          return py::make_tuple(copy_vector(i), copy_vector(j));
        },
        "Reference O(N^2) pair search (for tests): pairs closer than r_i + r_j + skin.");
  m.def("neighbor_pairs",
        [](const World& w) {
          const NeighborList& nb = w.neighbors();
          std::vector<Index> i, j;
          for (std::size_t a = 0; a + 1 < nb.start.size(); ++a)
            for (Index k = nb.start[a]; k < nb.start[a + 1]; ++k) { i.push_back(static_cast<Index>(a)); j.push_back(nb.j[k]); }
          return py::make_tuple(copy_vector(i), copy_vector(j));
        },
        "The world's current neighbour pairs (i < j) as two arrays.");
}
