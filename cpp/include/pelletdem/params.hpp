#pragma once
// Parameter tables: every parameter of a law is one row, written once, from which its struct
// field, its check, its binding, the Python dataclass field and the docs' table are made (the
// way Yade's YADE_CLASS_BASE_DOC_ATTRS lists a class's attributes). A row is
//
//   X(type, name, default, check, lo, hi, unit, label, lanes, doc)
//
// type: double or bool. check: how a value is checked (Check below) against [lo, hi]. unit:
// SI unit ("-" dimensionless). label: the name in error messages. lanes: false when the
// pair loop's four-lane kernel does not implement the row, so that a value off its default
// sends every pair through the scalar kernel (HystereticLaw::plain_pairs); rows that never
// act on particle pairs (walls, stages, bonds) are true. doc: one line for users.
#include <cmath>
#include <string>
#include <vector>

#include "pelletdem/errors.hpp"

namespace pelletdem {

enum class Check {
  None,         // a flag, or anything finite in [lo, hi]
  Range,        // lo <= value <= hi
  Positive,     // finite and > 0 (and in [lo, hi])
  NonNegative,  // finite and >= 0 (and in [lo, hi])
  ZeroOrRange,  // 0 (off), or lo <= value <= hi
  WholeRange,   // a whole number with lo <= value <= hi
};

// One row of a table, as the bindings and the docs read it.
struct ParamRow {
  std::string name, type;
  double def, lo, hi;
  Check check;
  std::string unit, label;
  bool lanes;
  std::string doc;
};

// The message an out-of-range value gets: it names the parameter, its value and what is allowed.
inline void check_param(Check check, const char* label, double value, double lo, double hi,
                        const char* unit) {
  const char* u = (unit[0] == '-' && unit[1] == '\0') ? "" : unit;
  switch (check) {
    case Check::None:
      return;
    case Check::Positive:
      require_positive(label, value, u);
      if (value < lo || value > hi) require_range(label, value, lo, hi, u);
      return;
    case Check::NonNegative:
      require_nonnegative(label, value, u);
      if (value < lo || value > hi) require_range(label, value, lo, hi, u);
      return;
    case Check::ZeroOrRange:
      if (value != 0.0) require_range(label, value, lo, hi, u);
      return;
    case Check::WholeRange:
      require_range(label, value, lo, hi, u);
      require(value == std::floor(value), cat(label, " = ", value, " must be a whole number"));
      return;
    case Check::Range:
      require_range(label, value, lo, hi, u);
      return;
  }
}

// Rows of a table as ParamRow values (for the bindings and the docs).
#define PELLETDEM_PARAM_ROW(type, name, def, check, lo, hi, unit, label, lanes, doc) \
  ParamRow{#name, #type, static_cast<double>(def), lo, hi, Check::check, unit, label, lanes, doc},
// A struct field with its default.
#define PELLETDEM_PARAM_FIELD(type, name, def, check, lo, hi, unit, label, lanes, doc) type name = def;
// The field checked against its row.
#define PELLETDEM_PARAM_CHECK(type, name, def, check, lo, hi, unit, label, lanes, doc) \
  check_param(Check::check, label, static_cast<double>(name), lo, hi, unit);
// True while every row that the four-lane kernel lacks keeps its default.
#define PELLETDEM_PARAM_LANES(type, name, def, check, lo, hi, unit, label, lanes, doc) \
  &&(lanes || name == static_cast<type>(def))
// True while every row keeps its default.
#define PELLETDEM_PARAM_AT_DEFAULT(type, name, def, check, lo, hi, unit, label, lanes, doc) \
  &&(name == static_cast<type>(def))

}  // namespace pelletdem
