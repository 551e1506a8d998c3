// The partial derivatives of the whole free flow (free_flow.hpp) in its 11 inputs: the moments (3),
// L0 (3), q0 (4, any norm) and t, with the derivative conventions of frbjax/_body.py's `motion_once`
// at its degenerate points, so that frbjax/_free_flow.py's JVP rule is one product with this matrix
// (a custom call and a contraction for XLA to compile, instead of the composite's derivative program).
//
// Three cases per point, as `motion_once` takes them:
// - moving bodies: the derivatives of the formulas taken (the working frame and |L|, the working
//   motion of motion.hpp, the quaternion products), by the chain rule on dual numbers: the working
//   motion's own 7 partial derivatives (its order-1 instantiation) carried into the 11 inputs;
// - uniform rotations (docs/theory.md §6): the solution of the variational equations of the uniform
//   rotation (frbjax/_uniform.py's `_response`), whose values are L(t) = L0, q(t) = q0 ⊗ exp(t Omega0/2);
// - symmetric bodies next to the plane of their equal moments: the derivatives of the first-order
//   expansion of their regular precession (frbjax/_precession.py's `precession`), on dual numbers.
// The values are free_flow.hpp's.  An invalid body (free_flow.hpp's checks) gets NaN everywhere.
#pragma once

#include <cmath>
#include <limits>

#include "free_flow.hpp"

namespace frbjax {

constexpr int kFlowInputs = 11;      // moments (3), L0 (3), q0 (4), t
constexpr int kFlowOutputs = 7;      // L(t) (3), q(t) (4)
constexpr double kPlaneBand = 0.125;  // frbjax/_precession.py's PLANE_BAND

// (f1, f2, f3)(y) = sum_k (-y)^k / (2k + j)!, j = 1, 2, 3: at x = sqrt(y), sin x / x, (1 - cos x) / x^2 and
// (x - sin x) / x^3 (sinh, cosh of sqrt(-y) for y < 0; DLMF 4.19.1-2, 4.33.1-2), as
// frbjax/_uniform.py's `response_functions`: its Taylor series where the closed forms cancel.
template <class T>
void response_functions(const T& y, T* f) {
  using std::sin;
  using std::sinh;
  using std::sqrt;
  constexpr int kTerms = 14;
  const double limits[3] = {1.0, 1.0, 4.0};
  const double y_value = double(value(y));
  const double magnitude = y_value < 0 ? -y_value : y_value;
  const bool growing = y_value < 0;
  bool closed_needed = false;
  for (int j = 0; j < 3; ++j) closed_needed = closed_needed || !(magnitude < limits[j]);
  T closed[3];
  if (closed_needed) {
    // cosh and sinh of more overflow (`_LARGEST_GROWTH`): the argument is held at 700^2 there.
    const T argument = growing ? (-y_value > 490000.0 ? T(490000.0) : -y) : y;
    const T x = sqrt(argument);
    const T sin_x = growing ? sinh(x) : sin(x);
    const T half = growing ? sinh(x / 2.0) : sin(x / 2.0);
    closed[0] = sin_x / x;
    closed[1] = 2.0 * half * half / (x * x);
    closed[2] = (growing ? sin_x - x : x - sin_x) / (x * x * x);
  }
  for (int j = 0; j < 3; ++j) {
    if (!(magnitude < limits[j])) {
      f[j] = closed[j];
      continue;
    }
    // Horner's scheme from the last term, (-1)^k / (2k + j + 1)!.
    double coefficients[kTerms];
    double factorial = 1;
    for (int n = 2; n <= j + 1; ++n) factorial *= n;
    for (int k = 0; k < kTerms; ++k) {
      coefficients[k] = (k % 2 == 0 ? 1.0 : -1.0) / factorial;
      factorial *= double(2 * k + j + 2) * double(2 * k + j + 3);
    }
    T sum = T(coefficients[kTerms - 1]);
    for (int k = kTerms - 2; k >= 0; --k) sum = sum * y + coefficients[k];
    f[j] = sum;
  }
}

template <class T>
void cross(const T* a, const T* b, T* out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

// The Hamilton product p ⊗ q (w, x, y, z) without fused products: for derivatives.
template <class T>
void hamilton_product(const T* p, const T* q, T* out) {
  out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3];
  out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2];
  out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1];
  out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0];
}

// (delta L(t), phi(t)) of a uniform rotation (frbjax/_uniform.py's `_response`, principal frame): the
// solution of the variational equations for the changes d_moments and d_momentum of its inputs.
template <class R>
void uniform_response(const R* moments, const R* momentum, R t, const R* d_moments, const R* d_momentum,
                      R* d_angular_momentum, R* phi) {
  const R size_squared = momentum[0] * momentum[0] + momentum[1] * momentum[1] + momentum[2] * momentum[2];
  const bool spinning = size_squared > 0;
  const R root = std::sqrt(spinning ? size_squared : R(1));
  R unit[3];
  for (int k = 0; k < 3; ++k) unit[k] = spinning ? momentum[k] / root : R(k == 0);
  const R size = spinning ? root : R(0);
  R omega = 0;
  for (int k = 0; k < 3; ++k) omega += unit[k] * unit[k] / moments[k];
  R gaps[3];
  for (int k = 0; k < 3; ++k) gaps[k] = 1 / moments[k] - omega;
  auto across = [&](const R* v, R* out) {  // A v / |L0| = n x (D v)
    const R scaled[3] = {gaps[0] * v[0], gaps[1] * v[1], gaps[2] * v[2]};
    cross(unit, scaled, out);
  };
  const R n1 = unit[0] * unit[0], n2 = unit[1] * unit[1], n3 = unit[2] * unit[2];
  const R kappa = size_squared * (n1 * gaps[1] * gaps[2] + n2 * gaps[0] * gaps[2] + n3 * gaps[0] * gaps[1]);
  R f[3];
  response_functions<R>(kappa * t * t, f);
  const R sine = t * f[0], versine = t * t * f[1], excess = t * t * t * f[2];

  // b / |L0| and the forced part W: delta L(t) gets |L0| W, phi gets -n x W.
  R pull[3], forcing[3], once[3], twice[3], forced[3];
  for (int k = 0; k < 3; ++k) pull[k] = unit[k] * d_moments[k] / (moments[k] * moments[k]);
  cross(unit, pull, forcing);
  for (int k = 0; k < 3; ++k) forcing[k] = -size * forcing[k];
  across(forcing, once);
  across(once, twice);
  for (int k = 0; k < 3; ++k)
    forced[k] = t * forcing[k] + versine * size * once[k] + excess * size_squared * twice[k];
  R turned[3], turned_twice[3];
  across(d_momentum, turned);
  across(turned, turned_twice);
  for (int k = 0; k < 3; ++k)
    d_angular_momentum[k] = d_momentum[k] + sine * size * turned[k] + versine * size_squared * turned_twice[k] +
                            size * forced[k];

  const R spin_angle = t * omega * size;
  R g[3];
  response_functions<R>(spin_angle * spin_angle, g);
  R normal[3], unit_normal[3], unit_turned[3], unit_turned_twice[3], unit_forced[3];
  cross(unit, d_momentum, normal);
  cross(unit, normal, unit_normal);
  cross(unit, turned, unit_turned);
  cross(unit, turned_twice, unit_turned_twice);
  cross(unit, forced, unit_forced);
  R along = 0, pulled = 0;
  for (int k = 0; k < 3; ++k) {
    along += unit[k] / moments[k] * d_momentum[k];
    pulled += unit[k] * unit[k] * d_moments[k] / (moments[k] * moments[k]);
  }
  const R parallel = t * (along - size * pulled);
  for (int k = 0; k < 3; ++k)
    phi[k] = -t * omega * (g[0] * unit_normal[k] + spin_angle * g[1] * normal[k]) - sine * unit_turned[k] -
             versine * size * unit_turned_twice[k] - unit_forced[k] + parallel * unit[k];
}

// Whether a body takes the precession's derivatives (frbjax/_precession.py's `precessing`): exactly two
// equal moments, not a uniform rotation, unit L within kPlaneBand of the plane of the equal moments.
template <class R>
bool precessing(const R* moments, const R* momentum, int regime) {
  const bool odd[3] = {moments[1] == moments[2], moments[0] == moments[2], moments[0] == moments[1]};
  if (int(odd[0]) + int(odd[1]) + int(odd[2]) != 1 || regime == kUniform) return false;
  const int e = odd[0] ? 0 : odd[1] ? 1 : 2;
  const R size_squared = momentum[0] * momentum[0] + momentum[1] * momentum[1] + momentum[2] * momentum[2];
  return momentum[e] * momentum[e] < R(kPlaneBand * kPlaneBand) * size_squared;
}

// (L(t), s(t)) of the first-order expansion of a symmetric body's regular precession
// (frbjax/_precession.py's `precession`, principal frame, its module docstring's formulas), on any
// number type: the attitude is q0 ⊗ s(t).
template <class T>
void precession(const T* moments, const T* momentum, const T& t, T* angular_momentum, T* spin) {
  using std::cos;
  using std::sin;
  using std::sqrt;
  const int e = value(moments[1]) == value(moments[2]) ? 0 : value(moments[0]) == value(moments[2]) ? 1 : 2;
  const int u = (e + 1) % 3, v = (e + 2) % 3;  // (u, v, e) cyclic: right-handed
  const T alpha = 2.0 / (moments[u] + moments[v]);  // 1 / the equal pair's mean
  const T gap = 1.0 / moments[e] - alpha;
  const T unequal = (1.0 / moments[u] - 1.0 / moments[v]) / 2.0;  // zero in value
  const T &l_u = momentum[u], &l_v = momentum[v], &l_e = momentum[e];
  const T size = sqrt(l_u * l_u + l_v * l_v + l_e * l_e);

  // Q(t) turns by -nu t about e; the repeated integrals of cos and sin(2 nu s).
  const T half = gap * l_e * t / 2.0;
  const T half_cosine = cos(half), half_sine = sin(half);
  const T cosine = 1.0 - 2.0 * half_sine * half_sine, sine = 2.0 * half_sine * half_cosine;
  const T twice_angle = 4.0 * half;
  T f[3];
  response_functions<T>(twice_angle * twice_angle, f);
  const T once_cosine = t * f[0], once_sine = t * twice_angle * f[1];
  const T twice_cosine = t * t * f[1], twice_sine = t * t * twice_angle * f[2];
  const T difference = l_u * l_u - l_v * l_v, product = l_u * l_v;
  const T along_twice = unequal * (twice_sine * difference - 2.0 * twice_cosine * product);  // e . F2
  const T drift = gap * along_twice;
  const T x_u = unequal * l_e * (once_cosine * l_v - once_sine * l_u) + drift * l_v;
  const T x_v = unequal * l_e * (once_cosine * l_u + once_sine * l_v) - drift * l_u;
  const T x_e = unequal * (once_sine * difference - 2.0 * once_cosine * product);
  angular_momentum[u] = cosine * (l_u + x_u) + sine * (l_v + x_v);
  angular_momentum[v] = cosine * (l_v + x_v) - sine * (l_u + x_u);
  angular_momentum[e] = l_e + x_e;

  // psi = -n x x / |L0| + (n . psi) n; s(t) = exp(t alpha L0 / 2) ⊗ exp(nu t e / 2) ⊗ (1, phi / 2).
  const T n_u = l_u / size, n_v = l_v / size, n_e = l_e / size;
  const T parallel = gap * n_e * along_twice + unequal * (once_cosine * difference + 2.0 * once_sine * product) / size;
  const T psi_u = -(n_v * x_e - n_e * x_v) / size + parallel * n_u;
  const T psi_v = -(n_e * x_u - n_u * x_e) / size + parallel * n_v;
  const T psi_e = -(n_u * x_v - n_v * x_u) / size + parallel * n_e;
  const T spin_angle = alpha * size * t / 2.0;
  const T spin_cosine = cos(spin_angle), spin_sine = sin(spin_angle);
  const T crossed = spin_sine * half_sine;
  const T s_w = spin_cosine * half_cosine - crossed * n_e;
  const T s_u = spin_sine * half_cosine * n_u + crossed * n_v;
  const T s_v = spin_sine * half_cosine * n_v - crossed * n_u;
  const T s_e = spin_cosine * half_sine + spin_sine * half_cosine * n_e;
  const T p_u = (cosine * psi_u + sine * psi_v) / 2.0, p_v = (cosine * psi_v - sine * psi_u) / 2.0,
          p_e = psi_e / 2.0;
  spin[0] = s_w - (s_u * p_u + s_v * p_v + s_e * p_e);
  spin[1 + u] = s_u + s_w * p_u + (s_v * p_e - s_e * p_v);
  spin[1 + v] = s_v + s_w * p_v + (s_e * p_u - s_u * p_e);
  spin[1 + e] = s_e + s_w * p_e + (s_u * p_v - s_v * p_u);
}

// values (7) and jacobian (7 x 11, row-major) of the free flow of one body (free_flow.hpp's inputs).
template <class R>
void free_flow_jacobian(const R* inertia, const R* momentum, const R* attitude, R t, R* values, R* jacobian) {
  using D = Dual<R, kFlowInputs>;
  free_flow<R>(inertia, momentum, attitude, t, values, values + 3);
  if (!valid_body(inertia, momentum, attitude)) {
    for (int k = 0; k < kFlowOutputs * kFlowInputs; ++k) jacobian[k] = std::numeric_limits<R>::quiet_NaN();
    return;
  }
  D moments[3], angular_momentum[3], quaternion[4], time(0.0);
  for (int k = 0; k < 3; ++k) {
    moments[k] = D(0.0);
    moments[k].v = inertia[k];
    moments[k].d[k] = R(1);
    angular_momentum[k] = D(0.0);
    angular_momentum[k].v = momentum[k];
    angular_momentum[k].d[3 + k] = R(1);
  }
  for (int k = 0; k < 4; ++k) {
    quaternion[k] = D(0.0);
    quaternion[k].v = attitude[k];
    quaternion[k].d[6 + k] = R(1);
  }
  time.v = t;
  time.d[10] = R(1);
  // q0 / |q0|: the body's unit attitude, as `_prepare` normalises it.
  D start[4];
  {
    const D inverse = 1.0 / sqrt(quaternion[0] * quaternion[0] + quaternion[1] * quaternion[1] +
                                 quaternion[2] * quaternion[2] + quaternion[3] * quaternion[3]);
    for (int k = 0; k < 4; ++k) start[k] = quaternion[k] * inverse;
  }
  D result[kFlowOutputs];
  const WorkingFrame<R> frame = working_frame<R>(inertia, momentum);

  if (frame.regime == kUniform) {
    // L(t) = L0 and q(t) = start ⊗ s, s = exp(t Omega0 / 2), with the variational solution: dL(t) and
    // d s = s ⊗ (0, phi / 2) for changes of the moments and L0; d s / dt = s ⊗ (0, Omega0 / 2).
    R rotation[3], spin[4];
    for (int k = 0; k < 3; ++k) rotation[k] = t * (momentum[k] / inertia[k]);
    exp_pure(rotation, spin);
    for (int k = 0; k < kFlowOutputs; ++k) result[k] = D(0.0);
    for (int c = 0; c < 6; ++c) {
      R d_moments[3] = {0, 0, 0}, d_momentum[3] = {0, 0, 0}, d_state[3], phi[3];
      (c < 3 ? d_moments[c] : d_momentum[c - 3]) = R(1);
      uniform_response<R>(inertia, momentum, t, d_moments, d_momentum, d_state, phi);
      const R half_turn[4] = {R(0), phi[0] / 2, phi[1] / 2, phi[2] / 2};
      R turned[4];
      hamilton_product(spin, half_turn, turned);
      for (int k = 0; k < 3; ++k) result[k].d[c] = d_state[k];
      for (int k = 0; k < 4; ++k) result[3 + k].d[c] = turned[k];
    }
    const R half_velocity[4] = {R(0), momentum[0] / inertia[0] / 2, momentum[1] / inertia[1] / 2,
                                momentum[2] / inertia[2] / 2};
    R rate[4];
    hamilton_product(spin, half_velocity, rate);
    for (int k = 0; k < 4; ++k) result[3 + k].d[10] = rate[k];
    // d(start ⊗ s ⊗ (1, phi / 2)) = d start ⊗ s + start ⊗ d(s ⊗ ...): the first from start's duals.
    D fixed_spin[4], turned[4], moved[4];
    for (int k = 0; k < 4; ++k) {
      fixed_spin[k] = D(spin[k]);
      for (int c = 0; c < kFlowInputs; ++c) turned[k].d[c] = result[3 + k].d[c];
    }
    hamilton_product(start, fixed_spin, moved);
    D start_values[4];
    for (int k = 0; k < 4; ++k) start_values[k] = D(start[k].v);
    D carried[4];
    for (int k = 0; k < 4; ++k) turned[k].v = R(0);
    hamilton_product(start_values, turned, carried);
    for (int k = 0; k < 4; ++k) result[3 + k] = moved[k] + carried[k];
  } else {
    // The working frame P and the regime are locally constant: L_w = P^T L, J_w the sorted moments.
    D working_moments[3], working_momentum[3];
    for (int k = 0; k < 3; ++k) {
      working_momentum[k] = D(0.0);
      for (int i = 0; i < 3; ++i) {
        if (frame.permutation[i][k] != 0) working_moments[k] = moments[i];
        working_momentum[k] += angular_momentum[i] * double(frame.permutation[i][k]);
      }
    }
    const D norm = sqrt(working_momentum[0] * working_momentum[0] + working_momentum[1] * working_momentum[1] +
                        working_momentum[2] * working_momentum[2]);
    D inputs[kMotionInputs];
    for (int k = 0; k < 3; ++k) {
      inputs[k] = working_moments[k];
      inputs[3 + k] = working_momentum[k] / norm;
    }
    inputs[6] = norm * time;
    // The working motion's partial derivatives in its own 7 inputs, carried into the 11.
    using W = Dual<R, kMotionInputs>;
    W seeded[kMotionInputs], motion[kMotionOutputs];
    const R input_values[kMotionInputs] = {frame.inertia[0],       frame.inertia[1],       frame.inertia[2],
                                           frame.unit_momentum[0], frame.unit_momentum[1], frame.unit_momentum[2],
                                           frame.norm * t};
    for (int j = 0; j < kMotionInputs; ++j) {
      seeded[j] = W(0.0);
      seeded[j].v = input_values[j];
      seeded[j].d[j] = R(1);
    }
    working_motion<W>(seeded, frame.regime, true, motion);
    D carried[kMotionOutputs];
    for (int o = 0; o < kMotionOutputs; ++o) {
      carried[o] = D(0.0);
      carried[o].v = motion[o].v;
      for (int j = 0; j < kMotionInputs; ++j)
        for (int c = 0; c < kFlowInputs; ++c) carried[o].d[c] += motion[o].d[j] * inputs[j].d[c];
    }
    // L(t) = |L| P l̂(tau); q(t) = start ⊗ (w, P v) with (w, v) = conj(q̂(0)) ⊗ q̂(tau), normalised.
    for (int i = 0; i < 3; ++i) {
      D turned(0.0);
      for (int k = 0; k < 3; ++k) turned += carried[k] * double(frame.permutation[i][k]);
      result[i] = norm * turned;
    }
    const D conjugate_start[4] = {carried[3], -carried[4], -carried[5], -carried[6]};
    D change[4], body_change[4], product[4];
    hamilton_product(conjugate_start, carried + 7, change);
    body_change[0] = change[0];
    for (int i = 0; i < 3; ++i) {
      body_change[1 + i] = D(0.0);
      for (int k = 0; k < 3; ++k) body_change[1 + i] += change[1 + k] * double(frame.permutation[i][k]);
    }
    hamilton_product(start, body_change, product);
    const D inverse = 1.0 / sqrt(product[0] * product[0] + product[1] * product[1] + product[2] * product[2] +
                                 product[3] * product[3]);
    for (int k = 0; k < 4; ++k) result[3 + k] = product[k] * inverse;

    if (precessing<R>(inertia, momentum, frame.regime)) {
      // The expansion's derivatives in place of the formulas' (its values are theirs to rounding).
      D spin[4];
      precession<D>(moments, angular_momentum, time, result, spin);
      hamilton_product(start, spin, result + 3);
    }
  }
  for (int o = 0; o < kFlowOutputs; ++o)
    for (int c = 0; c < kFlowInputs; ++c) jacobian[o * kFlowInputs + c] = result[o].d[c];
}

}  // namespace frbjax
