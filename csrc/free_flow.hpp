// The whole forward free flow of a body with principal moments at one time per point: the compiled
// form of frbjax/_body.py's `_motion_once` (axes None, with the attitude), whose values it returns.
//
// Per point: the checks of `_prepare` (an invalid body gives NaN everywhere), the unit attitude, the
// working frame and |L| (docs/theory.md §2), the regime from exact tests (`_regimes.classify`, §3 and
// §6), then either the uniform rotation (§6, frbjax/_uniform.py: L constant, q0 ⊗ exp(t Omega0 / 2))
// or the working-frame motion of motion.hpp at tau = |L| t, turned back to the body (§2, §8):
//   L(t) = |L| P l̂(tau),   q(t) = q0 ⊗ (w, P v)  with  (w, v) = conj(q̂(0)) ⊗ q̂(tau).
//
// Rounding.  The working frame, |L|, the unit L and the energy gaps must round exactly as the JAX path
// compiled by XLA:CPU does, so that both take the same regime on the same side of every exact test
// (the separatrix g2 = 0, the axis spins g1 = 0 or g3 = 0, the symmetric bodies' planes).  This file
// is compiled without contraction (-ffp-contract=off, CMakeLists.txt: it lies outside motion.hpp's
// fused region, and GCC does not inline across the two settings), and the products and sums that
// XLA:CPU contracts are written out as `multiply_add`, in the order LLVM fuses them (an fmul feeding
// an fadd or fsub becomes its FMA, the first operand's product first); the energy gaps are sums of
// quotients, which nothing fuses.  XLA also rewrites a division by a broadcast |L| as a product with
// its reciprocal, which the unit L copies.  The attitude's normalisations are XLA's x * rsqrt(|x|^2)
// with a hardware estimate refined by Newton steps (not portable); here x * (1 / sqrt(|x|^2)), within
// an ulp or two of it.  (As x / sqrt(|x|^2) a unit q was moved by an ulp more often: two splitting
// trajectories whose torques differ by rounding drifted apart by 10 ulp in 20 steps, tests/test_torques.py,
// where they stay within one.)  tests/test_compiled_free_flow.py checks the regimes and |L| P l̂ bit
// for bit.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "motion.hpp"

namespace frbjax {

constexpr int kFreeFlowFrameOutputs = 8;  // regime, |L|, J (3), unit l (3): for the tests

// a * b + c as XLA:CPU rounds it: one FMA where the kernels fuse the motion (FRBJAX_FUSED_MOTION, set
// where XLA:CPU uses FMA instructions), two roundings elsewhere.
template <class T>
FRBJAX_INLINE T multiply_add(T a, T b, T c) {
#ifdef FRBJAX_FUSED_MOTION
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

// sum_k v_k^2 over N components, as frbjax._fusion.sum_last(v * v): ((v0 v0 + v1 v1) + v2 v2) + ...
template <int N, class T>
FRBJAX_INLINE T sum_of_squares(const T* v) {
  T total = multiply_add(v[0], v[0], v[1] * v[1]);
  for (int k = 2; k < N; ++k) total = multiply_add(v[k], v[k], total);
  return total;
}

// matrix @ vector for a 3 x 3 matrix (`_frame.matrix_times`: each row's products summed in order).
template <class T>
FRBJAX_INLINE void matrix_times(const T (&matrix)[3][3], const T* vector, T* out) {
  for (int i = 0; i < 3; ++i)
    out[i] = multiply_add(matrix[i][2], vector[2], multiply_add(matrix[i][0], vector[0], matrix[i][1] * vector[1]));
}

// The Hamilton product p ⊗ q (w, x, y, z) of frbjax/_quaternion.py's `multiply`, each component's
// products summed in the written order.
template <class T>
FRBJAX_INLINE void hamilton(const T* p, const T* q, T* out) {
  const T &pw = p[0], &px = p[1], &py = p[2], &pz = p[3];
  const T &qw = q[0], &qx = q[1], &qy = q[2], &qz = q[3];
  out[0] = multiply_add(-pz, qz, multiply_add(-py, qy, multiply_add(pw, qw, -(px * qx))));
  out[1] = multiply_add(-pz, qy, multiply_add(py, qz, multiply_add(pw, qx, px * qw)));
  out[2] = multiply_add(pz, qx, multiply_add(py, qw, multiply_add(pw, qy, -(px * qz))));
  out[3] = multiply_add(pz, qw, multiply_add(-py, qx, multiply_add(pw, qz, px * qy)));
}

// a x b on any number type.
template <class T>
void cross(const T* a, const T* b, T* out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

// The Hamilton product p ⊗ q (w, x, y, z) on any number type (dual numbers too), unfused.
template <class T>
void hamilton_product(const T* p, const T* q, T* out) {
  out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3];
  out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2];
  out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1];
  out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0];
}

// v / |v| for a quaternion, as v times 1/|v|: XLA's form, v rsqrt(|v|^2) (its reciprocal square root
// is correctly rounded at 86% of points and within 2 ulp at the others).
template <class T>
FRBJAX_INLINE void normalise_quaternion(T* v) {
  const T inverse_norm = T(1) / std::sqrt(sum_of_squares<4>(v));
  for (int k = 0; k < 4; ++k) v[k] = v[k] * inverse_norm;
}

// The regime from exact tests only (`_regimes.energy_gaps` and `classify`, the same operations in the
// same order): the energy gaps g1 = 1 - d J1, g2 = d J2 - 1, g3 = d J3 - 1 without cancellation
// (docs/theory.md §3) decide the side of the separatrix, and the uniform rotations are the exact
// cases of §6 (L = 0, a sphere, spin about an extreme axis, on the separatrix level the middle axis
// or the plane of a symmetric body's equal moments).
template <class T>
FRBJAX_INLINE int classify(const T* j, const T* l, T norm) {
  const T &j1 = j[0], &j2 = j[1], &j3 = j[2];
  const T l1s = l[0] * l[0], l2s = l[1] * l[1], l3s = l[2] * l[2];
  const T g1 = l2s * (j2 - j1) / j2 + l3s * (j3 - j1) / j3;
  const T g3 = l1s * (j3 - j1) / j1 + l2s * (j3 - j2) / j2;
  const T g2 = l1s * (j2 - j1) / j1 - l3s * (j3 - j2) / j3;
  const bool uniform = norm == 0 || j1 == j3 || (g2 < 0 && g3 == 0) || (g2 > 0 && g1 == 0) ||
                       (g2 == 0 && (j1 == j2 || j2 == j3 || (l[0] == 0 && l[2] == 0)));
  if (uniform) return kUniform;
  return g2 < 0 ? kMajor : g2 > 0 ? kMinor : kSeparatrix;
}

// The working frame of docs/theory.md §2 (`_body.working_frame` and `_prepare`): the signed
// permutation P (det +1, columns the working axes in body coordinates), the sorted moments
// J1 <= J2 <= J3, |L|, the unit working momentum l = P^T L / |L| (l1 >= 0, l3 >= 0) and the regime.
template <class T>
struct WorkingFrame {
  T permutation[3][3];
  T inertia[3];
  T unit_momentum[3];
  T norm;
  int regime;
};

template <class T>
FRBJAX_INLINE WorkingFrame<T> working_frame(const T* inertia, const T* momentum) {
  const T &j1 = inertia[0], &j2 = inertia[1], &j3 = inertia[2];
  // Stable ranks (ties keep their order): body axis i becomes working axis rank[i].
  const int rank[3] = {int(j2 < j1) + int(j3 < j1), int(j1 <= j2) + int(j3 < j2), int(j1 <= j3) + int(j2 <= j3)};
  // An odd permutation has determinant -1: its middle working axis is flipped.
  const int parity = (rank[1] - rank[0]) * (rank[2] - rank[0]) * (rank[2] - rank[1]) > 0 ? 1 : -1;
  const T column_sign[3] = {T(1), T(parity), T(1)};
  WorkingFrame<T> frame;
  T transposed[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      // As _body.working_frame builds it: 0/1 times the column's sign (zeros keep their signs).
      frame.permutation[i][k] = T(rank[i] == k) * column_sign[k];
      transposed[k][i] = frame.permutation[i][k];
    }
  for (int k = 0; k < 3; ++k) frame.inertia[k] = rank[0] == k ? j1 : rank[1] == k ? j2 : j3;
  // P^T L (exact: a signed permutation), then the rotations by pi about a working axis that make
  // l1 >= 0 and l3 >= 0.
  T working[3];
  matrix_times(transposed, momentum, working);
  const T s1 = working[0] < 0 ? T(-1) : T(1), s3 = working[2] < 0 ? T(-1) : T(1);
  const T flips[3] = {s1, s1 * s3, s3};
  for (int k = 0; k < 3; ++k) {
    working[k] = working[k] * flips[k];
    for (int i = 0; i < 3; ++i) frame.permutation[i][k] = frame.permutation[i][k] * flips[k];
  }
  // |L| from the working components, in the order of the sorted moments: it rounds the same way for
  // the moments in any order.
  const T norm_squared = sum_of_squares<3>(working);
  const bool moving = norm_squared > 0;
  const T norm = std::sqrt(moving ? norm_squared : T(1));
  const T inverse = T(1) / norm;
  for (int k = 0; k < 3; ++k) frame.unit_momentum[k] = working[k] * inverse;
  frame.norm = moving ? norm : T(0);
  frame.regime = classify(frame.inertia, frame.unit_momentum, frame.norm);
  return frame;
}

// `_prepare`'s test of a valid body: moments > 0 and finite, L and q finite, q not zero.
template <class T>
bool valid_body(const T* inertia, const T* momentum, const T* attitude) {
  bool valid = true, turned = false;
  for (int k = 0; k < 3; ++k) valid = valid && inertia[k] > 0 && std::isfinite(inertia[k]);
  for (int k = 0; k < 3; ++k) valid = valid && std::isfinite(momentum[k]);
  for (int k = 0; k < 4; ++k) {
    valid = valid && std::isfinite(attitude[k]);
    turned = turned || attitude[k] != 0;
  }
  return valid && turned;
}

// exp(v / 2) as a unit quaternion (frbjax/_quaternion.py's `exp_pure`): the series 1 - theta^2/8 and
// 1/2 - theta^2/48 below theta^2 = 1e-8.
template <class T>
void exp_pure(const T* rotation, T* out) {
  const T theta_squared = sum_of_squares<3>(rotation);
  const bool small = theta_squared < T(1e-8);
  const T theta = std::sqrt(small ? T(1) : theta_squared);
  const T scalar = small ? T(1) - theta_squared / T(8) : std::cos(theta / T(2));
  const T vector_scale = small ? T(0.5) - theta_squared / T(48) : std::sin(theta / T(2)) / theta;
  out[0] = scalar;
  for (int k = 0; k < 3; ++k) out[1 + k] = vector_scale * rotation[k];
}

// The body's state from its working-frame motion (motion.hpp's outputs): L(t) = |L| P l̂(tau) and
// q = q0 ⊗ p ⊗ conj(q̂(0)) ⊗ q̂(tau) ⊗ conj(p) (docs/theory.md §8), where p ⊗ (w, v) ⊗ conj(p) =
// (w, P v): the working-frame rotation conj(q̂(0)) ⊗ q̂(tau) with its axis taken to body axes.
template <class T>
FRBJAX_INLINE void body_state(const T (&permutation)[3][3], T norm, const T* start, const T* motion,
                              T* momentum_out, T* attitude_out) {
  T turned[3];
  matrix_times(permutation, motion, turned);
  for (int k = 0; k < 3; ++k) momentum_out[k] = norm * turned[k];
  const T* chart_start = motion + 3;
  const T* chart_now = motion + 7;
  const T conjugate_start[4] = {chart_start[0], -chart_start[1], -chart_start[2], -chart_start[3]};
  T change[4];
  hamilton(conjugate_start, chart_now, change);
  T body_change[4] = {change[0]};
  matrix_times(permutation, change + 1, body_change + 1);
  hamilton(start, body_change, attitude_out);
  // Three products and the chart leave |q| - 1 at up to ~20 ulp (`_body._normalised`).
  normalise_quaternion(attitude_out);
}

// (L(t), q(t)) of one body: inertia (3, principal moments, any order), momentum L0 (3), attitude q0
// (4, w x y z, any nonzero norm), t.
template <class T>
void free_flow(const T* inertia, const T* momentum, const T* attitude, T t, T* momentum_out, T* attitude_out) {
  if (!valid_body(inertia, momentum, attitude)) {
    for (int k = 0; k < 3; ++k) momentum_out[k] = std::numeric_limits<T>::quiet_NaN();
    for (int k = 0; k < 4; ++k) attitude_out[k] = std::numeric_limits<T>::quiet_NaN();
    return;
  }
  T start[4] = {attitude[0], attitude[1], attitude[2], attitude[3]};
  normalise_quaternion(start);
  const WorkingFrame<T> frame = working_frame(inertia, momentum);

  if (frame.regime == kUniform) {
    // Omega0 parallel to L0 (docs/theory.md §6): L(t) = L0 and q(t) = q0 ⊗ exp(t Omega0 / 2),
    // Omega0 = L0 / I (frbjax/_uniform.py's values).
    T rotation[3], spin[4];
    for (int k = 0; k < 3; ++k) {
      momentum_out[k] = momentum[k];
      rotation[k] = t * (momentum[k] / inertia[k]);
    }
    exp_pure(rotation, spin);
    hamilton(start, spin, attitude_out);
    return;
  }

  // The unit problem at tau = |L| t in the working frame (motion.hpp).
  const T in[kMotionInputs] = {frame.inertia[0],       frame.inertia[1],       frame.inertia[2],
                               frame.unit_momentum[0], frame.unit_momentum[1], frame.unit_momentum[2],
                               frame.norm * t};
  T motion[kMotionOutputs];
  working_motion<T>(in, frame.regime, true, motion);
  body_state(frame.permutation, frame.norm, start, motion, momentum_out, attitude_out);
}

// Up to kBlock bodies at once (`free_flow` of each): the working frames point by point, the
// working-frame motion of the elliptic regimes as motion.hpp's block (its straight-line stages
// vectorised), and `body_state` as one loop over the bodies.  Invalid and uniformly rotating bodies
// take `free_flow` itself.  (This file fuses nothing, so its loops round the same, vectorised or not.)
template <class R>
void free_flow_block(const R* inertia, const R* momentum, const R* attitude, const R* t, int count,
                     R* momentum_out, R* attitude_out) {
  R in[kMotionInputs][kBlock], permutation[3][3][kBlock], start[4][kBlock], norm[kBlock];
  int regime[kBlock];
  for (int i = 0; i < count; ++i) {
    const WorkingFrame<R> frame = working_frame(inertia + 3 * i, momentum + 3 * i);
    regime[i] = frame.regime;
    for (int k = 0; k < 3; ++k) {
      in[k][i] = frame.inertia[k];
      in[3 + k][i] = frame.unit_momentum[k];
      for (int c = 0; c < 3; ++c) permutation[k][c][i] = frame.permutation[k][c];
    }
    in[6][i] = frame.norm * t[i];
    norm[i] = frame.norm;
    R unit[4] = {attitude[4 * i], attitude[4 * i + 1], attitude[4 * i + 2], attitude[4 * i + 3]};
    normalise_quaternion(unit);
    for (int k = 0; k < 4; ++k) start[k][i] = unit[k];
  }
  fill_stand_ins(in, count);
  // Invalid and uniformly rotating bodies: `free_flow` itself; the block's stages pass them by.
  bool alone[kBlock];
  for (int i = 0; i < count; ++i) {
    alone[i] = regime[i] == kUniform || !valid_body(inertia + 3 * i, momentum + 3 * i, attitude + 4 * i);
    if (!alone[i]) continue;
    regime[i] = kUniform;
    free_flow<R>(inertia + 3 * i, momentum + 3 * i, attitude + 4 * i, t[i], momentum_out + 3 * i, attitude_out + 4 * i);
  }
  R motion[kMotionOutputs][kBlock];
  working_motion_block<R, true>(in, regime, count, motion);
  R state[7][kBlock];
  // Vectorised without `omp simd`, which GCC 12 does not apply to a loop with a local array.
  for (int i = 0; i < count; ++i) {
    R point_permutation[3][3], point_start[4], point_motion[kMotionOutputs], point_state[7];
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < 3; ++c) point_permutation[k][c] = permutation[k][c][i];
    for (int k = 0; k < 4; ++k) point_start[k] = start[k][i];
    for (int k = 0; k < kMotionOutputs; ++k) point_motion[k] = motion[k][i];
    body_state(point_permutation, norm[i], point_start, point_motion, point_state, point_state + 3);
    for (int k = 0; k < 7; ++k) state[k][i] = point_state[k];
  }
  for (int i = 0; i < count; ++i) {
    if (alone[i]) continue;
    for (int k = 0; k < 3; ++k) momentum_out[3 * i + k] = state[k][i];
    for (int k = 0; k < 4; ++k) attitude_out[4 * i + k] = state[3 + k][i];
  }
}

// For the tests: the regime (as a number), |L|, the sorted moments and the unit working momentum of
// `working_frame`, to compare bit for bit with `_body._prepare`'s.
template <class T>
void free_flow_frame(const T* inertia, const T* momentum, T* out) {
  const WorkingFrame<T> frame = working_frame(inertia, momentum);
  out[0] = T(frame.regime);
  out[1] = frame.norm;
  for (int k = 0; k < 3; ++k) out[2 + k] = frame.inertia[k];
  for (int k = 0; k < 3; ++k) out[5 + k] = frame.unit_momentum[k];
}

}  // namespace frbjax
