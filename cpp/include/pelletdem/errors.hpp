#pragma once
// Engine errors. The bindings map ParameterError to Python's ValueError subclass and the
// others to RuntimeError subclasses, so a user always gets a named Python exception.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pelletdem {

// Bad input, raised before any work starts; the message names the parameter and its range.
struct ParameterError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// The state went wrong during a run (NaN, escape, overlap beyond the guard).
struct SimulationError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ParticleEscapedError : SimulationError {
  using SimulationError::SimulationError;
};

struct OverlapError : SimulationError {
  using SimulationError::SimulationError;
};

struct NonFiniteError : SimulationError {
  using SimulationError::SimulationError;
};

template <class... Args>
std::string cat(const Args&... args) {
  std::ostringstream os;
  os.precision(6);
  (os << ... << args);
  return os.str();
}

inline void require(bool ok, const std::string& message) {
  if (!ok) throw ParameterError(message);
}

// Finite and inside [lo, hi]; the message names the parameter and the range.
inline void require_range(const char* name, double value, double lo, double hi, const char* unit = "") {
  if (!(value >= lo && value <= hi))  // also catches NaN
    throw ParameterError(cat(name, " = ", value, " ", unit, " is out of range: allowed ", lo, " <= ", name,
                             " <= ", hi, " ", unit));
}

inline void require_positive(const char* name, double value, const char* unit = "") {
  if (!(value > 0.0) || !std::isfinite(value))
    throw ParameterError(cat(name, " = ", value, " ", unit, " must be a finite number > 0"));
}

inline void require_nonnegative(const char* name, double value, const char* unit = "") {
  if (!(value >= 0.0) || !std::isfinite(value))
    throw ParameterError(cat(name, " = ", value, " ", unit, " must be a finite number >= 0"));
}

}  // namespace pelletdem
