// The World: construction, walls, settings, runs (in chunks with the GIL released, so Ctrl-C and
// progress callbacks are served between chunks, never inside the step loop), views of the
// particle arrays, time series, contacts and bonds.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "bindings.hpp"

namespace pelletdem::bindings {

namespace {

// Runs the engine in chunks with the GIL released; returns (condition index, steps run).
// `between(done)` is called only when the run goes on after a chunk: the world then sits
// between two steps and no stop condition has fired, so a checkpoint taken there resumes
// exactly (one taken after the chunk that met a condition would run past it on resume).
py::tuple run_chunked(World& w, std::vector<StopCondition> conds, long max_steps, const py::object& progress,
                      const py::object& between) {
  if (max_steps < 0) throw ParameterError(cat("max_steps = ", max_steps, " must be >= 0"));
  // "Steps" counts over the whole call, so it becomes the budget rather than a per-chunk test.
  std::vector<int> index_map;
  std::vector<StopCondition> inner;
  long steps_limit = max_steps;
  int steps_index = -1;
  for (std::size_t k = 0; k < conds.size(); ++k) {
    if (conds[k].kind == StopKind::Steps) {
      if (!(conds[k].value >= 0)) throw ParameterError("stop condition steps must be >= 0");
      if (conds[k].value <=
          static_cast<double>(steps_limit)) {  // compared as doubles: 1e300 must not overflow a long
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
    if (done >= steps_limit)
      return py::make_tuple(done >= max_steps && steps_index < 0 ? -1 : steps_index, done);
    if (!between.is_none()) between(done);
    // Aim for ~0.1 s per chunk so an interrupt is served well within a second.
    if (seconds > 0.0)
      chunk = std::clamp(static_cast<long>(this_chunk * 0.1 / seconds), 1L, 1000000L);
    else
      chunk = std::min(chunk * 4, 1000000L);
  }
}

}  // namespace

void bind_world(py::module_& m) {
  py::class_<World>(m, "World")
      .def(py::init<const WorldParams&>(), py::arg("params"))
      .def("clone", &World::clone)
      .def(
          "sort_particles", [](World& w) { return copy_vector(w.sort_particles()); },
          "Renumber the particles in Morton order of their neighbour cells; returns the old "
          "index of each new particle.")
      .def(
          "get_state", [](const World& w) { return state_to_dict(w.save_state()); },
          "The whole state as a dict of numpy arrays (see pelletdem.checkpoint).")
      .def("set_state", &set_world_state, py::arg("state"),
           "Restore a state from get_state() into a world built with the same parameters.")
      .def(
          "add_particles",
          [](World& w, const py::object& x, const py::object& r) {
            w.add_particles(to_vec3_array(x, "positions"), to_vector(r, "radii"));
          },
          py::arg("positions"), py::arg("radii"))
      .def(
          "add_plane",
          [](World& w, const std::string& name, const std::vector<double>& point,
             const std::vector<double>& normal) {
            return w.add_plane(name, to_vec3(point, "point"), to_vec3(normal, "normal"));
          },
          py::arg("name"), py::arg("point"), py::arg("normal"))
      .def(
          "add_cylinder",
          [](World& w, const std::string& name, const std::vector<double>& axis_point, double radius) {
            return w.add_cylinder(name, to_vec3(axis_point, "axis_point"), radius);
          },
          py::arg("name"), py::arg("axis_point"), py::arg("radius"))
      .def_property_readonly("wall_count", &World::wall_count)
      .def("wall_name", [](const World& w, int k) { return w.wall(k).name; })
      .def("wall_kind",
           [](const World& w, int k) { return w.wall(k).kind == WallKind::Plane ? "plane" : "cylinder"; })
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
             if (w.wall(k).kind != WallKind::Cylinder)
               throw ParameterError("radius_rate applies to cylinders only");
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
             try {
               wl.validate();
             } catch (...) {
               wl.servo = false;
               throw;
             }
           })
      .def("set_wall_active",
           [](World& w, int k, bool a) {
             w.wall(k).active = a;
             w.invalidate();
           })
      .def(
          "set_wall_crushable",
          [](World& w, int k, bool c) {
            w.wall(k).crushable = c;
            w.invalidate();
          },
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
      .def_property(
          "dt", [](const World& w) { return w.params().dt; }, &World::set_dt)
      .def_property(
          "threads", [](const World& w) { return w.params().threads; }, &World::set_threads)
      .def_property(
          "gravity",
          [](const World& w) {
            const Vec3& g = w.params().gravity;
            return std::vector<double>{g.x(), g.y(), g.z()};
          },
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
      .def_property_readonly(
          "sample_interval", [](const World& w) { return w.params().sample_interval; },
          "Steps between time-series samples.")
      .def_property_readonly(
          "max_overlap_ratio", [](const World& w) { return w.params().max_overlap_ratio; },
          "The overlap guard: delta / r beyond it stops a run.")
      .def("step",
           [](World& w) {
             py::gil_scoped_release r;
             w.step();
           })
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
      .def("mean_velocity",
           [](const World& w) {
             Vec3 v = w.mean_velocity();
             return std::vector<double>{v.x(), v.y(), v.z()};
           })
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
      .def("track_load_peak", &World::track_load_peak, py::arg("from_marker"),
           py::arg("smoothing_steps") = 1.0,
           "Average the load force over ~smoothing_steps steps and keep its peak from the load marker "
           "from_marker (m) on, for the load_drop_below stop (inf: stop keeping them).")
      .def("critical_time_step", &World::critical_time_step,
           "Stability limit of the stiffest spring the laws can reach on the lightest particle, s.")
      .def("max_time_step", &World::max_time_step,
           "The largest dt the world accepts: kTimeStepSafety of critical_time_step(), s.")
      .def(
          "time_step_springs",
          [](const World& w) {
            py::list out;
            for (const TimeStepSpring& s : w.time_step_springs())
              out.append(py::dict(py::arg("what") = s.what, py::arg("k") = s.k, py::arg("k_eff") = s.k_eff,
                                  py::arg("zeta") = s.zeta, py::arg("dt_limit") = s.dt_limit));
            return out;
          },
          "Each spring the laws can reach: what (str), k and k_eff (N/m), zeta (-), dt_limit (s).")
      .def_property_readonly("rebuild_count", &World::rebuild_count)
      .def_property_readonly("pair_list_size", [](const World& w) { return w.neighbors().pair_count(); })
      // Read-only zero-copy views.
      .def_property_readonly("x",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().x.data(), w.particles().size(), 3, self);
                             })
      .def_property_readonly("v",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().v.data(), w.particles().size(), 3, self);
                             })
      .def_property_readonly("w",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().w.data(), w.particles().size(), 3, self);
                             })
      .def_property_readonly("f",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().f.data(), w.particles().size(), 3, self);
                             })
      .def_property_readonly("t",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().t.data(), w.particles().size(), 3, self);
                             })
      .def_property_readonly("r",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().r.data(), w.particles().size(), 1, self);
                             })
      .def_property_readonly("m",
                             [](py::object self) {
                               World& w = self.cast<World&>();
                               return view_of(w, w.particles().m.data(), w.particles().size(), 1, self);
                             })
      .def("set_velocities",
           [](World& w, const py::object& v, const py::object& omega) {
             auto vv = to_vec3_array(v, "velocities");
             auto ww = to_vec3_array(omega, "angular velocities");
             auto& p = w.particles();
             if (vv.size() != p.size() || ww.size() != p.size())
               throw ParameterError(cat("velocities must have shape (", p.size(), ", 3)"));
             for (auto& x : vv)
               if (!x.allFinite()) throw ParameterError("velocities must be finite");
             for (auto& x : ww)
               if (!x.allFinite()) throw ParameterError("angular velocities must be finite");
             p.v = vv;
             p.w = ww;
             w.invalidate();
           })
      .def("set_positions",
           [](World& w, const py::object& x) {
             auto xx = to_vec3_array(x, "positions");
             auto& p = w.particles();
             if (xx.size() != p.size())
               throw ParameterError(cat("positions must have shape (", p.size(), ", 3)"));
             for (auto& q : xx)
               if (!q.allFinite()) throw ParameterError("positions must be finite");
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
               t[k] = s[k].time;
               ke[k] = s[k].kinetic_energy;
               cn[k] = s[k].coordination_number;
               ov[k] = s[k].max_overlap_ratio;
               lm[k] = s[k].load_marker;
               nc[k] = s[k].n_contacts;
               nbi[k] = s[k].n_bonds_intact;
               nbb[k] = s[k].n_bonds_broken;
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
             if (k < 0 || k >= w.wall_count())
               throw ParameterError(cat("wall index ", k, " out of range 0..", w.wall_count() - 1));
             const auto& s = w.wall_samples(k);
             const std::size_t n = s.size();
             std::vector<double> t(n), fn(n), rad(n), tr(n);
             std::vector<Vec3> f(n), pt(n);
             for (std::size_t q = 0; q < n; ++q) {
               t[q] = s[q].time;
               fn[q] = s[q].normal_force;
               rad[q] = s[q].radius;
               tr[q] = s[q].travel;
               f[q] = s[q].force;
               pt[q] = s[q].point;
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
      .def("create_bonds",
           [](World& w, const BondParams& p) {
             py::gil_scoped_release r;
             return w.create_bonds(p);
           })
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
               i[k] = b[k].i;
               j[k] = b[k].j;
               mode[k] = static_cast<std::uint8_t>(b[k].mode);
               fn[k] = b[k].fn;
               mn[k] = b[k].mn;
               ft[k] = b[k].ft;
               mt[k] = b[k].mt;
               rad[k] = b[k].radius;
               kn[k] = b[k].kn;
               kt[k] = b[k].kt;
               sc[k] = b[k].sigma_c;
               tc[k] = b[k].tau_c;
               sig[k] = b[k].sigma_max();
               tau[k] = b[k].tau_max();
               dmg[k] = b[k].damage;
             }
             py::dict d;
             d["i"] = copy_vector(i);
             d["j"] = copy_vector(j);
             d["mode"] = copy_vector(mode);
             d["fn"] = copy_vector(fn);
             d["ft"] = copy_vec3(ft);
             d["mn"] = copy_vector(mn);
             d["mt"] = copy_vec3(mt);
             d["radius"] = copy_vector(rad);
             d["kn"] = copy_vector(kn);
             d["kt"] = copy_vector(kt);
             d["sigma_c"] = copy_vector(sc);
             d["tau_c"] = copy_vector(tc);
             d["damage"] = copy_vector(dmg);
             d["sigma_max"] = copy_vector(sig);
             d["tau_max"] = copy_vector(tau);
             return d;
           })
      .def("set_bond_property",
           [](World& w, const std::string& name, const py::object& values) {
             auto v = to_vector(values, name.c_str());
             auto& b = w.bonds_mut();
             if (v.size() != b.size())
               throw ParameterError(
                   cat(name, " must have one value per bond (", b.size(), "), got ", v.size()));
             for (std::size_t k = 0; k < v.size(); ++k)
               if (!(v[k] > 0.0) || !std::isfinite(v[k]))
                 throw ParameterError(cat(name, "[", k, "] = ", v[k], " must be finite and > 0"));
             double Bond::* field = nullptr;
             if (name == "radius")
               field = &Bond::radius;
             else if (name == "kn")
               field = &Bond::kn;
             else if (name == "kt")
               field = &Bond::kt;
             else if (name == "sigma_c")
               field = &Bond::sigma_c;
             else if (name == "tau_c")
               field = &Bond::tau_c;
             else
               throw ParameterError(
                   cat("unknown bond property '", name, "': allowed radius, kn, kt, sigma_c, tau_c"));
             for (std::size_t k = 0; k < v.size(); ++k) b[k].*field = v[k];
           })
      .def("broken_bonds", [](const World& w) { return broken_to_dict(w.broken_bonds()); });
}

}  // namespace pelletdem::bindings
