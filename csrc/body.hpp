// A FreeRigidBody's per-body data and its evaluation in the body frame (values; the derivatives are the
// flow kernels', flow_jacobian.hpp): the compiled form of frbjax/_body.py's `_construct` and of the
// methods' `_momentum_from` and `_attitude_from` around the theta series (series.hpp), so that building
// a body is one custom call and each evaluation another.
//
// `body_record`: the checks of `_prepare` (an invalid body's record is NaN), the unit attitude, L in
// the principal frame (R^T L0 for principal axes R, components of rounding size zeroed), the working
// frame, |L| and the regime (free_flow.hpp's, docs/theory.md §2, §3, §6), the series record (series.hpp),
// and the constant maps of docs/theory.md §8:
//   L(t) = |L| P l̂(tau),   q(t) = M q̂(tau),  M p = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ p ⊗ conj(P),
// (P: the working frame as a rotation, R P for principal axes R), and for a uniform rotation (§6)
// L(t) = L0, q(t) = q0 ⊗ exp(t Omega0 / 2) with Omega0 = R (R^T L0 / I).
// `body_state`: (L(t), q(t)) from a record at times t.
#pragma once

#include <cmath>
#include <limits>

#include "free_flow.hpp"
#include "series.hpp"

namespace frbjax {

template <class R>
struct BodyLayout {
  using Series = SeriesLayout<R>;
  enum : int {
    kNorm = Series::size,             // |L|, NaN for an invalid body
    kRegime = kNorm + 1,              // as a number
    kPermutation = kRegime + 1,       // 3 x 3, row-major: columns the working axes in body coordinates
    kAttitudeMap = kPermutation + 9,  // 4 x 4, row-major: q(t) = M q̂(tau) (before normalising)
    kVelocity = kAttitudeMap + 16,    // Omega0, body frame
    kMomentum = kVelocity + 3,        // L0, body frame
    kAttitude = kMomentum + 3,        // unit q0
    kSortedInertia = kAttitude + 4,   // J1 <= J2 <= J3
    kUnitMomentum = kSortedInertia + 3,
    kPrincipalPermutation = kUnitMomentum + 3,  // 3 x 3: the working frame in principal coordinates
  };
  static constexpr int size = kPrincipalPermutation + 9;
};

// frbjax/_body.py's `_FRAME_ROUNDING`: principal components of L within this many ulp of |L| are zeros.
constexpr double kFrameRounding = 64;

// The unit quaternion of a rotation matrix by Shepperd's method (frbjax/_quaternion.py's `from_matrix`:
// the largest of 1 + tr R and 1 + 2 R_ii - tr R under the square root).
template <class R>
void quaternion_from_matrix(const R (&r)[3][3], R* q) {
  const R trace = r[0][0] + r[1][1] + r[2][2];
  const R candidates[4] = {1 + trace, 1 + 2 * r[0][0] - trace, 1 + 2 * r[1][1] - trace, 1 + 2 * r[2][2] - trace};
  int choice = 0;
  for (int k = 1; k < 4; ++k)
    if (candidates[k] > candidates[choice]) choice = k;
  const R largest = std::sqrt(candidates[choice]) / 2;
  const R quarter = 1 / (4 * largest);
  switch (choice) {
    case 0:
      q[0] = largest, q[1] = (r[2][1] - r[1][2]) * quarter, q[2] = (r[0][2] - r[2][0]) * quarter,
      q[3] = (r[1][0] - r[0][1]) * quarter;
      break;
    case 1:
      q[0] = (r[2][1] - r[1][2]) * quarter, q[1] = largest, q[2] = (r[0][1] + r[1][0]) * quarter,
      q[3] = (r[0][2] + r[2][0]) * quarter;
      break;
    case 2:
      q[0] = (r[0][2] - r[2][0]) * quarter, q[1] = (r[0][1] + r[1][0]) * quarter, q[2] = largest,
      q[3] = (r[1][2] + r[2][1]) * quarter;
      break;
    default:
      q[0] = (r[1][0] - r[0][1]) * quarter, q[1] = (r[0][2] + r[2][0]) * quarter,
      q[2] = (r[1][2] + r[2][1]) * quarter, q[3] = largest;
  }
}

// A body's record from its moments (3, along its principal axes), L0 (3) and q0 (4) in the body frame
// and its principal axes (3 x 3 row-major, columns the axes in body coordinates; nullptr: the body axes).
template <class R>
void body_record(const R* inertia, const R* momentum, const R* attitude, const R* axes, R* record) {
  using B = BodyLayout<R>;
  bool valid = valid_body(inertia, momentum, attitude);
  if (axes != nullptr)
    for (int k = 0; k < 9; ++k) valid = valid && std::isfinite(axes[k]);
  if (!valid) {
    for (int k = 0; k < B::size; ++k) record[k] = std::numeric_limits<R>::quiet_NaN();
    record[B::kRegime] = R(kUniform);
    return;
  }
  R unit_attitude[4];
  const R attitude_norm = std::sqrt(sum_of_squares<4>(attitude));
  for (int k = 0; k < 4; ++k) unit_attitude[k] = attitude[k] / attitude_norm;
  R principal[3];
  if (axes == nullptr) {
    for (int k = 0; k < 3; ++k) principal[k] = momentum[k];
  } else {
    for (int k = 0; k < 3; ++k) principal[k] = axes[k] * momentum[0] + axes[3 + k] * momentum[1] + axes[6 + k] * momentum[2];
    const R rounding = R(kFrameRounding) * std::numeric_limits<R>::epsilon() * std::sqrt(sum_of_squares<3>(principal));
    for (int k = 0; k < 3; ++k)
      if (std::fabs(principal[k]) <= rounding) principal[k] = 0;
  }
  const WorkingFrame<R> frame = working_frame<R>(inertia, principal);
  R permutation[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k)
      permutation[i][k] = axes == nullptr ? frame.permutation[i][k]
                                          : axes[3 * i] * frame.permutation[0][k] +
                                                axes[3 * i + 1] * frame.permutation[1][k] +
                                                axes[3 * i + 2] * frame.permutation[2][k];
  const R given[6] = {frame.inertia[0],       frame.inertia[1],       frame.inertia[2],
                      frame.unit_momentum[0], frame.unit_momentum[1], frame.unit_momentum[2]};
  series_record<R>(given, frame.regime, record);
  record[B::kNorm] = frame.norm;
  record[B::kRegime] = R(frame.regime);
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) record[B::kPermutation + 3 * i + k] = permutation[i][k];
  // M's columns: offset ⊗ e_k ⊗ conj(p), offset = q0 ⊗ p ⊗ conj(q̂(0)).
  R rotation[4], turned[4], offset[4];
  quaternion_from_matrix(permutation, rotation);
  const R* reference = record + SeriesLayout<R>::kReference;
  const R conjugate_reference[4] = {reference[0], -reference[1], -reference[2], -reference[3]};
  const R conjugate_rotation[4] = {rotation[0], -rotation[1], -rotation[2], -rotation[3]};
  hamilton_product(unit_attitude, rotation, turned);
  hamilton_product(turned, conjugate_reference, offset);
  for (int k = 0; k < 4; ++k) {
    R unit[4] = {0, 0, 0, 0}, column[4], mapped[4];
    unit[k] = 1;
    hamilton_product(offset, unit, column);
    hamilton_product(column, conjugate_rotation, mapped);
    for (int i = 0; i < 4; ++i) record[B::kAttitudeMap + 4 * i + k] = mapped[i];
  }
  // Omega0 = R (R^T L0 / I), the uniform rotation's.
  R principal_velocity[3];
  for (int k = 0; k < 3; ++k) principal_velocity[k] = principal[k] / inertia[k];
  for (int i = 0; i < 3; ++i)
    record[B::kVelocity + i] = axes == nullptr ? principal_velocity[i]
                                               : axes[3 * i] * principal_velocity[0] + axes[3 * i + 1] * principal_velocity[1] +
                                                     axes[3 * i + 2] * principal_velocity[2];
  for (int k = 0; k < 3; ++k) record[B::kMomentum + k] = momentum[k];
  for (int k = 0; k < 4; ++k) record[B::kAttitude + k] = unit_attitude[k];
  for (int k = 0; k < 3; ++k) {
    record[B::kSortedInertia + k] = frame.inertia[k];
    record[B::kUnitMomentum + k] = frame.unit_momentum[k];
  }
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) record[B::kPrincipalPermutation + 3 * i + k] = frame.permutation[i][k];
}

// L(t) (3) and, with `Attitude`, q(t) (4) of a body from its record at count <= kBlock times t:
// out (count, 7 or 3), row-major.
template <class R, bool Attitude>
void body_state_block(const R* record, const R* t, int count, R* out) {
  using B = BodyLayout<R>;
  constexpr int outputs = Attitude ? 7 : 3;
  if (record[B::kRegime] == R(kUniform)) {
    for (int i = 0; i < count; ++i) {
      R* point = out + outputs * i;
      for (int k = 0; k < 3; ++k) point[k] = record[B::kMomentum + k];
      if (!Attitude) continue;
      R rotation[3], spin[4];
      for (int k = 0; k < 3; ++k) rotation[k] = t[i] * record[B::kVelocity + k];
      exp_pure(rotation, spin);
      hamilton_product(record + B::kAttitude, spin, point + 3);
    }
    return;
  }
  const R norm = record[B::kNorm];
  R tau[kBlock], motion[7][kBlock], state[7][kBlock];
  for (int i = 0; i < count; ++i) tau[i] = norm * t[i];
  series_motion_block<R, Attitude>(record, tau, count, motion);
  const R* permutation = record + B::kPermutation;
  const R* map = record + B::kAttitudeMap;
#pragma omp simd
  for (int i = 0; i < count; ++i) {
    for (int k = 0; k < 3; ++k)
      state[k][i] = norm * (permutation[3 * k] * motion[0][i] + permutation[3 * k + 1] * motion[1][i] +
                            permutation[3 * k + 2] * motion[2][i]);
    if (!Attitude) continue;
    R moved[4];
    for (int k = 0; k < 4; ++k)
      moved[k] = map[4 * k] * motion[3][i] + map[4 * k + 1] * motion[4][i] + map[4 * k + 2] * motion[5][i] +
                 map[4 * k + 3] * motion[6][i];
    const R inverse_norm = 1 / std::sqrt(sum_of_squares<4>(moved));
    for (int k = 0; k < 4; ++k) state[3 + k][i] = moved[k] * inverse_norm;
  }
  for (int i = 0; i < count; ++i)
    for (int k = 0; k < outputs; ++k) out[outputs * i + k] = state[k][i];
}

}  // namespace frbjax
