// The laws' parameter structs, one attribute per row of their tables, and the tables; the
// world's construction parameters; stop conditions.
#include "bindings.hpp"

namespace pelletdem::bindings {

namespace {

const char* check_name(Check c) {
  switch (c) {
    case Check::None:
      return "none";
    case Check::Range:
      return "range";
    case Check::Positive:
      return "positive";
    case Check::NonNegative:
      return "nonnegative";
    case Check::ZeroOrRange:
      return "zero_or_range";
    case Check::WholeRange:
      return "whole_range";
  }
  return "?";
}

}  // namespace

void bind_laws(py::module_& m) {
  // The laws' parameters, one attribute per row of their tables (params.hpp), and the tables
  // themselves: the Python dataclasses, the checks and the docs are made from them.
  py::class_<ParamRow>(m, "ParamRow")
      .def_readonly("name", &ParamRow::name)
      .def_readonly("type", &ParamRow::type)
      .def_readonly("default", &ParamRow::def)
      .def_readonly("lo", &ParamRow::lo)
      .def_readonly("hi", &ParamRow::hi)
      .def_property_readonly("check", [](const ParamRow& r) { return check_name(r.check); })
      .def_readonly("unit", &ParamRow::unit)
      .def_readonly("label", &ParamRow::label)
      .def_readonly("lanes", &ParamRow::lanes)
      .def_readonly("doc", &ParamRow::doc);
#define PELLETDEM_BIND_FIELD(type, name, def, check, lo, hi, unit, label, lanes, doc) \
  .def_readwrite(#name, &Params::name, doc)
  {
    using Params = ContactLawParams;
    py::class_<ContactLawParams>(m, "ContactLawParams")
        .def(py::init<>()) PELLETDEM_CONTACT_ALL_ROWS(PELLETDEM_BIND_FIELD)
        .def("restitution", &ContactLawParams::restitution)
        .def("validate", &ContactLawParams::validate)
        .def("plain_pairs", &ContactLawParams::plain_pairs)
        .def("moisture_acts", &ContactLawParams::moisture_acts)
        .def("wood_density_acts", &ContactLawParams::wood_density_acts)
        .def_static("rows", &ContactLawParams::rows);
  }
  {
    using Params = BondParams;
    py::class_<BondParams>(m, "BondParams")
        .def(py::init<>()) PELLETDEM_BOND_ALL_ROWS(PELLETDEM_BIND_FIELD)
        .def("validate", &BondParams::validate)
        .def_static("rows", &BondParams::rows);
  }
#undef PELLETDEM_BIND_FIELD

  py::class_<WorldParams>(m, "WorldParams")
      .def(py::init<>())
      .def_readwrite("dt", &WorldParams::dt)
      .def_property(
          "gravity",
          [](const WorldParams& p) {
            return std::vector<double>{p.gravity.x(), p.gravity.y(), p.gravity.z()};
          },
          [](WorldParams& p, const std::vector<double>& g) { p.gravity = to_vec3(g, "gravity"); })
      .def_readwrite("density", &WorldParams::density)
      .def_readwrite("density_scale", &WorldParams::density_scale)
      .def_readwrite("skin", &WorldParams::skin)
      .def_property(
          "box_lo",
          [](const WorldParams& p) { return std::vector<double>{p.box.lo.x(), p.box.lo.y(), p.box.lo.z()}; },
          [](WorldParams& p, const std::vector<double>& g) { p.box.lo = to_vec3(g, "box_lo"); })
      .def_property(
          "box_hi",
          [](const WorldParams& p) { return std::vector<double>{p.box.hi.x(), p.box.hi.y(), p.box.hi.z()}; },
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
}

}  // namespace pelletdem::bindings
