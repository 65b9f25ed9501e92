// numpy arrays and lists in and out of the engine's types, each refused with a ParameterError
// naming the argument when its dtype, shape or values are wrong.
#include <algorithm>
#include <cstring>

#include "bindings.hpp"

namespace pelletdem::bindings {

namespace {
using Arr = py::array_t<double, py::array::c_style | py::array::forcecast>;
}  // namespace

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

}  // namespace pelletdem::bindings
