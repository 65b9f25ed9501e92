#pragma once
// Geometry types shared by the engine. Eigen's fixed 3-vectors are unaligned PODs of three
// doubles, so std::vector<Vec3> is a contiguous (N, 3) array that numpy can view without a copy.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace pelletdem {

using Vec3 = Eigen::Vector3d;
using Index = std::uint32_t;

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kHuge = 1.0e300;  // 'no limit' for forces, N

// The per-contact functions must fold into the pair loop; GCC otherwise keeps the law's
// evaluate() as a call, a quarter of the step's time.
#if defined(__GNUC__)
#define PELLETDEM_INLINE inline __attribute__((always_inline))
#else
#define PELLETDEM_INLINE inline
#endif

// Rodrigues rotation of v about the unit axis k by the angle with sine s and cosine c.
inline Vec3 rotate_about(const Vec3& v, const Vec3& k, double s, double c) {
  return v * c + k.cross(v) * s + k * (k.dot(v) * (1.0 - c));
}

// Rotate v by the smallest rotation that takes unit vector a onto unit vector b.
inline Vec3 rotate_a_to_b(const Vec3& v, const Vec3& a, const Vec3& b) {
  Vec3 axis = a.cross(b);
  const double s = axis.norm();
  if (s < 1e-14) return v;  // no tilt (or exact reversal, which one step never produces)
  axis /= s;
  return rotate_about(v, axis, s, a.dot(b));
}

}  // namespace pelletdem
