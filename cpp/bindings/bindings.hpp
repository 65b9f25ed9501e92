#pragma once
// What the bindings' files share: numpy conversions that refuse bad input with a named error,
// read-only views of the particle arrays, the world's state as a dict of arrays, and the
// functions that bind each part of the engine.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "pelletdem/errors.hpp"
#include "pelletdem/world.hpp"

namespace pelletdem::bindings {

namespace py = pybind11;

// --- conversions (convert.cpp) -------------------------------------------------------------
Vec3 to_vec3(const std::vector<double>& v, const char* name);
py::array real_array(const py::handle& obj, const char* name, const char* shape);
std::string shape_of(const py::array& a);
std::vector<Vec3> to_vec3_array(const py::handle& obj, const char* name);
std::vector<double> to_vector(const py::handle& obj, const char* name);
py::array_t<double> copy_vec3(const std::vector<Vec3>& v);

template <class T>
py::array_t<T> copy_vector(const std::vector<T>& v) {
  py::array_t<T> out(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(T));
  return out;
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
    out = py::array_t<double>(
        {N, static_cast<py::ssize_t>(3)},
        {static_cast<py::ssize_t>(sizeof(Vec3)), static_cast<py::ssize_t>(sizeof(double))},
        reinterpret_cast<const double*>(data), base);
  }
  out.attr("flags").attr("writeable") = false;
  return out;
}

// --- the world's state as a dict of numpy arrays (state_dict.cpp) --------------------------
py::dict broken_to_dict(const std::vector<BrokenBond>& b);
py::dict state_to_dict(const WorldState& s);
// Checks a state dict from get_state() whole, then loads it into w (ParameterError naming what
// is wrong, before anything changes).
void set_world_state(World& w, const py::object& state);

// --- the parts of the module ---------------------------------------------------------------
void bind_laws(py::module_& m);   // bind_laws.cpp: the laws' parameters, WorldParams, stops
void bind_world(py::module_& m);  // bind_world.cpp: World

}  // namespace pelletdem::bindings
