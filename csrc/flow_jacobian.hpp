// The partial derivatives of the whole free flow (free_flow.hpp) in its 11 inputs: the moments (3),
// L0 (3), q0 (4, any norm) and t, first (7 x 11) and second (7 x 11 x 11), with the derivative
// conventions of frbjax/_body.py's `motion_once` at its degenerate points, so that every JVP rule of
// the motion on the CPU (`free_flow`, a FreeRigidBody's evaluations: frbjax/_body.py's `flow_state`)
// is a product of these matrices with the tangents (a custom call and a contraction for XLA to
// compile, instead of the composite's derivative program).
//
// Three cases per point, as `motion_once` takes them:
// - moving bodies: the derivatives of the formulas taken (the working frame and |L|, the working
//   motion of motion.hpp, the quaternion products), by the chain rule on dual numbers: the working
//   motion's own 7 (and 7 x 7) partial derivatives, from its order-1 (order-2) instantiation, carried
//   into the 11 inputs;
// - uniform rotations (docs/theory.md §6): the solution of the variational equations of the uniform
//   rotation (frbjax/_uniform.py's `_response`), whose values are L(t) = L0, q(t) = q0 ⊗ exp(t Omega0/2);
//   its second derivatives are the rule's own, its coefficients frozen at the uniform rotation;
// - symmetric bodies next to the plane of their equal moments: the derivatives of the first-order
//   expansion of their regular precession (frbjax/_precession.py's `precession`), on dual numbers.
// The values are free_flow.hpp's.  An invalid body (free_flow.hpp's checks) gets NaN everywhere.
#pragma once

#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>

#include "free_flow.hpp"
#include "series.hpp"

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

// (delta L(t), phi(t)) of a uniform rotation (frbjax/_uniform.py's `_response`, principal frame): the
// solution of the variational equations for the changes d_moments and d_momentum of its inputs.  The
// uniform rotation's moments and L0 are constants of the rule (`_frozen`), t is of the number type T:
// differentiated again, the rule gives the second derivatives of the first-order expansion.
template <class R, class T>
void uniform_response(const R* moments, const R* momentum, const T& t, const R* d_moments, const R* d_momentum,
                      T* d_angular_momentum, T* phi) {
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
  T f[3];
  response_functions<T>(t * t * kappa, f);
  const T sine = t * f[0], versine = t * t * f[1], excess = t * t * t * f[2];

  // b / |L0| and the forced part W: delta L(t) gets |L0| W, phi gets -n x W.
  R pull[3], forcing[3], once[3], twice[3];
  for (int k = 0; k < 3; ++k) pull[k] = unit[k] * d_moments[k] / (moments[k] * moments[k]);
  cross(unit, pull, forcing);
  for (int k = 0; k < 3; ++k) forcing[k] = -size * forcing[k];
  across(forcing, once);
  across(once, twice);
  T forced[3];
  for (int k = 0; k < 3; ++k) forced[k] = t * forcing[k] + versine * (size * once[k]) + excess * (size_squared * twice[k]);
  R turned[3], turned_twice[3];
  across(d_momentum, turned);
  across(turned, turned_twice);
  for (int k = 0; k < 3; ++k)
    d_angular_momentum[k] = sine * (size * turned[k]) + versine * (size_squared * turned_twice[k]) + forced[k] * size +
                            d_momentum[k];

  const T spin_angle = t * (omega * size);
  T g[3];
  response_functions<T>(spin_angle * spin_angle, g);
  R normal[3], unit_normal[3], unit_turned[3], unit_turned_twice[3];
  cross(unit, d_momentum, normal);
  cross(unit, normal, unit_normal);
  cross(unit, turned, unit_turned);
  cross(unit, turned_twice, unit_turned_twice);
  const T unit_forced[3] = {forced[2] * unit[1] - forced[1] * unit[2], forced[0] * unit[2] - forced[2] * unit[0],
                            forced[1] * unit[0] - forced[0] * unit[1]};
  R along = 0, pulled = 0;
  for (int k = 0; k < 3; ++k) {
    along += unit[k] / moments[k] * d_momentum[k];
    pulled += unit[k] * unit[k] * d_moments[k] / (moments[k] * moments[k]);
  }
  const T parallel = t * (along - size * pulled);
  for (int k = 0; k < 3; ++k)
    phi[k] = -(t * omega) * (g[0] * unit_normal[k] + spin_angle * g[1] * normal[k]) - sine * unit_turned[k] -
             versine * (size * unit_turned_twice[k]) - unit_forced[k] + parallel * unit[k];
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

// The numbers of the flow's derivatives: Dual<R, 11> (first derivatives, .d[a]) and its nesting
// (.v.d[a] first, .d[b].d[a] = d/d_b of the first derivative in a).
template <class R>
using FlowDual = Dual<R, kFlowInputs>;
template <class R>
using FlowDual2 = Dual<FlowDual<R>, kFlowInputs>;

template <class R>
inline void seed(FlowDual<R>& x, R value, int index) {
  x = FlowDual<R>(0.0);
  x.v = value;
  x.d[index] = R(1);
}
template <class R>
inline void seed(FlowDual2<R>& x, R value, int index) {
  x = FlowDual2<R>(0.0);
  x.v.v = value;
  x.v.d[index] = R(1);
  x.d[index].v = R(1);
}

// The working motion's outputs as functions of the 11 inputs, by the chain rule from its own partial
// derivatives in its 7 inputs (motion.hpp on Dual<R, 7>, or nested for the second ones).
template <class R>
void carry(const Dual<R, kMotionInputs>* motion, const FlowDual<R>* inputs, FlowDual<R>* out) {
  for (int o = 0; o < kMotionOutputs; ++o) {
    out[o] = FlowDual<R>(0.0);
    out[o].v = motion[o].v;
    for (int j = 0; j < kMotionInputs; ++j)
      for (int c = 0; c < kFlowInputs; ++c) out[o].d[c] += motion[o].d[j] * inputs[j].d[c];
  }
}
template <class R>
void carry(const Dual<Dual<R, kMotionInputs>, kMotionInputs>* motion, const FlowDual2<R>* inputs, FlowDual2<R>* out) {
  for (int o = 0; o < kMotionOutputs; ++o) {
    const auto& m = motion[o];
    out[o] = FlowDual2<R>(0.0);
    out[o].v.v = m.v.v;
    for (int a = 0; a < kFlowInputs; ++a) {
      R first = 0;
      for (int j = 0; j < kMotionInputs; ++j) first += m.v.d[j] * inputs[j].v.d[a];
      out[o].v.d[a] = first;
      out[o].d[a].v = first;
    }
    for (int b = 0; b < kFlowInputs; ++b)
      for (int a = 0; a < kFlowInputs; ++a) {
        R second = 0;
        for (int j = 0; j < kMotionInputs; ++j) {
          second += m.v.d[j] * inputs[j].d[b].d[a];
          for (int k = 0; k < kMotionInputs; ++k) second += m.d[k].d[j] * inputs[j].v.d[a] * inputs[k].d[b].v;
        }
        out[o].d[b].d[a] = second;
      }
  }
}

template <class R>
using MotionDual1 = Dual<R, kMotionInputs>;
template <class R>
using MotionDual2 = Dual<MotionDual1<R>, kMotionInputs>;

template <class R>
void seed_motion(MotionDual1<R>& x, R value, int index) {
  x = MotionDual1<R>(0.0);
  x.v = value;
  x.d[index] = R(1);
}
template <class R>
void seed_motion(MotionDual2<R>& x, R value, int index) {
  x = MotionDual2<R>(0.0);
  x.v.v = value;
  x.v.d[index] = R(1);
  x.d[index].v = R(1);
}

// The working motion's inputs on the flow's numbers D: the working frame P (and the regime) locally
// constant, L_w = P^T L, the sorted moments, the unit L_w / |L| and tau = |L| t; and |L|.
template <class R, class D>
void flow_inputs(const WorkingFrame<R>& frame, const D* moments, const D* angular_momentum, const D& time, D* inputs,
                 D& norm) {
  D working_moments[3], working_momentum[3];
  for (int k = 0; k < 3; ++k) {
    working_momentum[k] = D(0.0);
    for (int i = 0; i < 3; ++i) {
      if (frame.permutation[i][k] != 0) working_moments[k] = moments[i];
      working_momentum[k] += angular_momentum[i] * double(frame.permutation[i][k]);
    }
  }
  norm = sqrt(working_momentum[0] * working_momentum[0] + working_momentum[1] * working_momentum[1] +
              working_momentum[2] * working_momentum[2]);
  for (int k = 0; k < 3; ++k) {
    inputs[k] = working_moments[k];
    inputs[3 + k] = working_momentum[k] / norm;
  }
  inputs[6] = norm * time;
}

// (L(t), q(t)) on the flow's numbers D from the working motion's outputs on M (their partial
// derivatives in its 7 inputs): L(t) = |L| P l̂(tau) and q(t) = start ⊗ (w, P v) with
// (w, v) = conj(q̂(0)) ⊗ q̂(tau), normalised (free_flow.hpp).
template <class R, class D, class M>
void flow_from_motion(const WorkingFrame<R>& frame, const D& norm, const D* inputs, const M* motion, const D* start,
                      D* result) {
  D carried[kMotionOutputs];
  carry(motion, inputs, carried);
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
  const D inverse =
      1.0 / sqrt(product[0] * product[0] + product[1] * product[1] + product[2] * product[2] + product[3] * product[3]);
  for (int k = 0; k < 4; ++k) result[3 + k] = product[k] * inverse;
}

// (L(t), q(t)) of a moving body on the flow's numbers D, the working motion (motion.hpp) on M.
template <class R, class D, class M>
void moving_flow(const WorkingFrame<R>& frame, R t, const D* moments, const D* angular_momentum, const D& time,
                 const D* start, D* result) {
  D inputs[kMotionInputs], norm;
  flow_inputs(frame, moments, angular_momentum, time, inputs, norm);
  const R input_values[kMotionInputs] = {frame.inertia[0],       frame.inertia[1],       frame.inertia[2],
                                         frame.unit_momentum[0], frame.unit_momentum[1], frame.unit_momentum[2],
                                         frame.norm * t};
  M seeded[kMotionInputs], motion[kMotionOutputs];
  for (int j = 0; j < kMotionInputs; ++j) seed_motion(seeded[j], input_values[j], j);
  working_motion<M>(seeded, frame.regime, true, motion);
  flow_from_motion<R, D, M>(frame, norm, inputs, motion, start, result);
}

// The uniform rotation's rule (frbjax/_uniform.py): the tangent of (L(t), q(t)) along each of the 11
// inputs, on the number type T (R; or FlowDual<R> for its own derivatives).  L(t) = L0 and
// q(t) = start ⊗ s with s = exp(t Omega0 / 2): d L(t) and d s = s ⊗ (0, rate / 2), rate = phi, for
// changes of the moments and L0 (`uniform_response`); d s / dt = s ⊗ (0, Omega0 / 2).  `start`,
// `spin` and `velocity` (Omega0 = L0 / I) carry, as T, their own derivatives: the rules'.
// The uniform rule along input a: d L(t) and the rate of the turn of s (phi for the moments and L0,
// Omega0 for t, nothing for q0).
template <class R, class T>
void uniform_rule(const R* moments, const R* momentum, const T& time, const T* velocity, int a, T* d_state, T* rate) {
  for (int k = 0; k < 3; ++k) d_state[k] = rate[k] = T(0.0);
  if (a < 6) {
    R d_moments[3] = {0, 0, 0}, d_momentum[3] = {0, 0, 0};
    (a < 3 ? d_moments[a] : d_momentum[a - 3]) = R(1);
    uniform_response<R, T>(moments, momentum, time, d_moments, d_momentum, d_state, rate);
  } else if (a == 10) {
    for (int k = 0; k < 3; ++k) rate[k] = velocity[k];
  }
}

template <class R, class T>
void uniform_tangents(const R* moments, const R* momentum, const T& time, const T* start, const T (*d_start)[4],
                      const T* spin, const T* velocity, T (*tangent)[kFlowInputs]) {
  for (int a = 0; a < kFlowInputs; ++a) {
    T d_state[3], rate[3];
    uniform_rule<R, T>(moments, momentum, time, velocity, a, d_state, rate);
    const T half_rate[4] = {T(0.0), rate[0] / 2.0, rate[1] / 2.0, rate[2] / 2.0};
    T turned[4], carried[4], moved[4];
    hamilton_product(spin, half_rate, turned);
    hamilton_product(start, turned, carried);
    hamilton_product(d_start[a], spin, moved);
    for (int k = 0; k < 3; ++k) tangent[k][a] = d_state[k];
    for (int k = 0; k < 4; ++k) tangent[3 + k][a] = moved[k] + carried[k];
  }
}

// The unit attitude q0 / |q0| (as `_prepare` normalises it) on the flow's numbers.
template <class D>
void unit_attitude(const D* quaternion, D* start) {
  const D inverse = 1.0 / sqrt(quaternion[0] * quaternion[0] + quaternion[1] * quaternion[1] +
                               quaternion[2] * quaternion[2] + quaternion[3] * quaternion[3]);
  for (int k = 0; k < 4; ++k) start[k] = quaternion[k] * inverse;
}

// Per output: its value (free_flow.hpp's), then its 11 first derivatives (Order 1), then (Order 2) the
// 11 x 11 second ones, [a][b] the derivative in b of the first one in a.  An invalid body gets NaN.
template <int Order>
constexpr int flow_width() {
  return Order == 1 ? 1 + kFlowInputs : 1 + kFlowInputs + kFlowInputs * kFlowInputs;
}

template <class R, int Order>
void free_flow_derivatives(const R* inertia, const R* momentum, const R* attitude, R t, R* out) {
  constexpr int W = flow_width<Order>();
  R values[kFlowOutputs];
  free_flow<R>(inertia, momentum, attitude, t, values, values + 3);
  if (!valid_body(inertia, momentum, attitude)) {
    for (int o = 0; o < kFlowOutputs; ++o) {
      out[o * W] = values[o];
      for (int k = 1; k < W; ++k) out[o * W + k] = std::numeric_limits<R>::quiet_NaN();
    }
    return;
  }
  using D = std::conditional_t<Order == 1, FlowDual<R>, FlowDual2<R>>;
  using M = std::conditional_t<Order == 1, MotionDual1<R>, MotionDual2<R>>;
  D moments[3], angular_momentum[3], quaternion[4], time;
  for (int k = 0; k < 3; ++k) {
    seed(moments[k], inertia[k], k);
    seed(angular_momentum[k], momentum[k], 3 + k);
  }
  for (int k = 0; k < 4; ++k) seed(quaternion[k], attitude[k], 6 + k);
  seed(time, t, 10);
  D start[4];
  unit_attitude(quaternion, start);
  const WorkingFrame<R> frame = working_frame<R>(inertia, momentum);

  // first[o][a] (and second[o][a][b] for Order 2).
  R first[kFlowOutputs][kFlowInputs], second[Order == 2 ? kFlowOutputs : 1][kFlowInputs][kFlowInputs];
  if (frame.regime == kUniform) {
    R rotation[3], spin[4], velocity[3];
    for (int k = 0; k < 3; ++k) {
      velocity[k] = momentum[k] / inertia[k];
      rotation[k] = t * velocity[k];
    }
    exp_pure(rotation, spin);
    R start_values[4], d_start[kFlowInputs][4];
    for (int k = 0; k < 4; ++k) {
      if constexpr (Order == 1) {
        start_values[k] = start[k].v;
        for (int a = 0; a < kFlowInputs; ++a) d_start[a][k] = start[k].d[a];
      } else {
        start_values[k] = start[k].v.v;
        for (int a = 0; a < kFlowInputs; ++a) d_start[a][k] = start[k].v.d[a];
      }
    }
    uniform_tangents<R, R>(inertia, momentum, t, start_values, d_start, spin, velocity, first);
    if constexpr (Order == 2) {
      // The rule's own derivatives: t, start, and the rules' derivatives of s and Omega0
      // (`_uniform_spin_jvp`'s uniform_momentum(...) / moments).
      using T = FlowDual<R>;
      T time_t(0.0), start_t[4], d_start_t[kFlowInputs][4], spin_t[4], velocity_t[3];
      time_t.v = t;
      time_t.d[10] = R(1);
      for (int k = 0; k < 4; ++k) {
        start_t[k] = start[k].v;
        for (int a = 0; a < kFlowInputs; ++a) {
          d_start_t[a][k] = T(0.0);
          d_start_t[a][k].v = start[k].v.d[a];
          for (int b = 0; b < kFlowInputs; ++b) d_start_t[a][k].d[b] = start[k].d[b].d[a];
        }
      }
      // d s along b = s ⊗ (0, rate_b / 2) = conj(start) ⊗ (q-tangent minus the start's part)...
      // computed directly: rate_b from the rule in R.
      for (int k = 0; k < 4; ++k) {
        spin_t[k] = T(0.0);
        spin_t[k].v = spin[k];
      }
      for (int k = 0; k < 3; ++k) {
        velocity_t[k] = T(0.0);
        velocity_t[k].v = velocity[k];
      }
      for (int b = 0; b < kFlowInputs; ++b) {
        R d_state[3], rate[3];
        uniform_rule<R, R>(inertia, momentum, t, velocity, b, d_state, rate);
        const R half_rate[4] = {R(0), rate[0] / 2, rate[1] / 2, rate[2] / 2};
        R d_spin[4];
        hamilton_product(spin, half_rate, d_spin);
        for (int k = 0; k < 4; ++k) spin_t[k].d[b] = d_spin[k];
        for (int k = 0; k < 3; ++k)
          velocity_t[k].d[b] = d_state[k] / inertia[k] - (b == k ? velocity[k] / inertia[k] : R(0));
      }
      T tangent[kFlowOutputs][kFlowInputs];
      uniform_tangents<R, T>(inertia, momentum, time_t, start_t, d_start_t, spin_t, velocity_t, tangent);
      for (int o = 0; o < kFlowOutputs; ++o)
        for (int a = 0; a < kFlowInputs; ++a)
          for (int b = 0; b < kFlowInputs; ++b) second[o][a][b] = tangent[o][a].d[b];
    }
  } else {
    D result[kFlowOutputs];
    moving_flow<R, D, M>(frame, t, moments, angular_momentum, time, start, result);
    if (precessing<R>(inertia, momentum, frame.regime)) {
      // The expansion's derivatives in place of the formulas' (its values are theirs to rounding).
      D spin[4];
      precession<D>(moments, angular_momentum, time, result, spin);
      hamilton_product(start, spin, result + 3);
    }
    for (int o = 0; o < kFlowOutputs; ++o)
      for (int a = 0; a < kFlowInputs; ++a) {
        if constexpr (Order == 1) {
          first[o][a] = result[o].d[a];
        } else {
          first[o][a] = result[o].v.d[a];
          for (int b = 0; b < kFlowInputs; ++b) second[o][a][b] = result[o].d[b].d[a];
        }
      }
  }
  for (int o = 0; o < kFlowOutputs; ++o) {
    out[o * W] = values[o];
    for (int a = 0; a < kFlowInputs; ++a) out[o * W + 1 + a] = first[o][a];
    if constexpr (Order == 2)
      for (int a = 0; a < kFlowInputs; ++a)
        for (int b = 0; b < kFlowInputs; ++b) out[o * W + 1 + kFlowInputs + a * kFlowInputs + b] = second[o][a][b];
  }
}

// The first derivatives of a FreeRigidBody's evaluations (its series, series.hpp) at one time per
// point, the points of one body at its times one after another: free_flow_derivatives<R, 1>'s
// output, from one record of dual numbers per body (the series' constants and their partial
// derivatives in the working moments and unit L, series_record on Dual<R, 7>) and the series at each
// tau on dual numbers (series_motion_point), instead of the one-time motion's constants on dual
// numbers at every point.  A body's record is kept while the next point has the same moments, L0 and
// q0 (bit for bit), so a point's result does not depend on its neighbours.  Bodies on the separatrix,
// uniform rotations, symmetric bodies next to the plane of their equal moments (the precession's
// derivatives) and invalid bodies take free_flow_derivatives<R, 1> itself.  Returns whether the
// series served the point.
template <class R>
struct SeriesFlow {
  bool ready = false;
  bool series = false;
  R key[10];
  WorkingFrame<R> frame;
  // The working motion's inputs on the flow's numbers (flow_inputs; tau, inputs[6], per point), |L|
  // and the unit q0: functions of the body alone.
  FlowDual<R> inputs[kMotionInputs], norm, start[4];
  MotionDual1<R> record[SeriesLayout<R>::size];
};

template <class R>
bool series_flow_derivatives(const R* inertia, const R* momentum, const R* attitude, R t, SeriesFlow<R>& body, R* out) {
  constexpr int W = flow_width<1>();
  const R key[10] = {inertia[0],  inertia[1],  inertia[2],  momentum[0], momentum[1],
                     momentum[2], attitude[0], attitude[1], attitude[2], attitude[3]};
  // Bit for bit (signed zeros apart too), so that the kept record is the one these inputs build.
  const bool same = body.ready && std::memcmp(key, body.key, sizeof key) == 0;
  if (!same) {
    for (int k = 0; k < 10; ++k) body.key[k] = key[k];
    body.ready = true;
    body.series = false;
    if (valid_body(inertia, momentum, attitude)) {
      body.frame = working_frame<R>(inertia, momentum);
      const int regime = body.frame.regime;
      body.series = (regime == kMajor || regime == kMinor) && !precessing<R>(inertia, momentum, regime);
    }
    if (body.series) {
      FlowDual<R> moments[3], angular_momentum[3], quaternion[4], time;
      for (int k = 0; k < 3; ++k) {
        seed(moments[k], inertia[k], k);
        seed(angular_momentum[k], momentum[k], 3 + k);
      }
      for (int k = 0; k < 4; ++k) seed(quaternion[k], attitude[k], 6 + k);
      unit_attitude(quaternion, body.start);
      seed(time, R(0), 10);
      flow_inputs(body.frame, moments, angular_momentum, time, body.inputs, body.norm);
      MotionDual1<R> seeded[6];
      for (int j = 0; j < 3; ++j) {
        seed_motion(seeded[j], body.frame.inertia[j], j);
        seed_motion(seeded[3 + j], body.frame.unit_momentum[j], 3 + j);
      }
      series_record<MotionDual1<R>>(seeded, body.frame.regime, body.record);
    }
  }
  if (!body.series) {
    free_flow_derivatives<R, 1>(inertia, momentum, attitude, t, out);
    return false;
  }
  using L = SeriesLayout<R>;
  FlowDual<R> time, result[kFlowOutputs];
  seed(time, t, 10);
  body.inputs[6] = body.norm * time;  // flow_inputs' tau
  MotionDual1<R> tau, now[7], motion[kMotionOutputs];
  seed_motion(tau, body.frame.norm * t, 6);
  series_motion_point<MotionDual1<R>>(body.record, tau, now);
  for (int k = 0; k < 3; ++k) motion[k] = now[k];
  for (int k = 0; k < 4; ++k) {
    motion[3 + k] = body.record[L::kReference + k];
    motion[7 + k] = now[3 + k];
  }
  flow_from_motion<R, FlowDual<R>, MotionDual1<R>>(body.frame, body.norm, body.inputs, motion, body.start, result);
  for (int o = 0; o < kFlowOutputs; ++o) {
    out[o * W] = result[o].v;
    for (int a = 0; a < kFlowInputs; ++a) out[o * W + 1 + a] = result[o].d[a];
  }
  return true;
}

}  // namespace frbjax
