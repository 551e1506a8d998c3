// The exact torque-free motion in the working frame at one time per body (docs/theory.md §4, §5, §11):
// the compiled form of frbjax/_regimes.py's `orbit_constants` and `evaluate_once`, per point, on any
// number type (values; dual numbers for the partial derivatives in the moments, the unit angular
// momentum and the time).
//
// The working frame has J1 <= J2 <= J3 and l1, l3 >= 0 (frbjax/_body.py's working_frame), so that every
// orbit sign is +1.  For each point: the regime's constants (the amplitudes A, the rate B, the
// parameter m and its complement mc without cancellation, alpha, the characteristic nu), then
//   L(tau) = A (cn, sn, dn)(u0 + B tau)  (major regime; (dn, sn, cn) in the minor one),
// from the given l and the Jacobi functions at v = B tau by the addition theorem (DLMF 22.8.1-22.8.3),
// and the precession angle
//   psi = tau / J_p + atan2 terms - alpha (Pi(nu; am u|m) [- u])  between 0 and tau,
// the third-kind integral's change from Jacobi's addition theorem for Pi (Whittaker and Watson 22.74),
// one R_J at the reduced point (DLMF 19.25.14) and the complete integral for whole half-periods
// (DLMF 19.2.10).  On the separatrix L and psi are elementary (hyperbolic functions of u).
//
// Outputs: unit L(tau) (3), the chart q̂(0) (4) and q̂(tau) (4), with psi counted from tau = 0, so that
// q(t) = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ q̂(tau) ⊗ conj(P) (docs/theory.md §8).  A uniformly rotating body
// (regime 3) gets L = l and identity charts: its motion is formed in JAX (frbjax/_uniform.py).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "carlson.hpp"
#include "circular.hpp"
#include "dual.hpp"
#include "jacobi.hpp"

namespace frbjax {

// q̂ = exp(psi/2 about the spatial axis) ⊗ (the rotation taking that axis to l), docs/theory.md §5:
// built on 1 + L1 (major regime, separatrix) or 1 + L3 (minor), in the order (w, x_p, y, z) or
// (w, y, z, x_p).  `_regimes._chart`.  Outside the fused section below: the series evaluation
// (series.hpp) inlines it into its loops over points, which fuse nothing.
template <class T>
void chart(const T& half_cos, const T& half_sin, const T& l1, const T& l2, const T& l3, bool minor, T* q) {
  using std::sqrt;
  const T& pivot = minor ? l3 : l1;
  const T& first = minor ? l2 : l3;
  const T& second = minor ? l1 : l2;
  T base = 1.0 + pivot;
  T root = sqrt(base / 2.0), inverse = 1.0 / sqrt(2.0 * base);
  T scalar = half_cos * root;
  T along_pivot = half_sin * root;
  T towards_first = (first * half_cos + second * half_sin) * inverse;
  T towards_second = (-second * half_cos + first * half_sin) * inverse;
  q[0] = scalar;
  q[1] = minor ? towards_first : along_pivot;
  q[2] = minor ? towards_second : towards_first;
  q[3] = minor ? along_pivot : towards_second;
}

}  // namespace frbjax

// In the FMA build of the kernels (frbjax._kernels_fma, chosen where the CPU has FMA instructions,
// as XLA:CPU's own code uses them there) this file's products and sums are fused where the compiler
// can: the one-time motion then rounds as the JAX path compiled by XLA does (XLA contracts a * b + c
// too), and the long time-reversal test (tests/test_body_invariants.py, |L| t = 100 and back) gives
// 1.0 eps |L| t instead of 3.3 without fusion.  Everywhere else the kernels fuse nothing
// (-ffp-contract=off in CMakeLists.txt): the special functions agree with the JAX path to the ulp.
#ifdef FRBJAX_FUSED_MOTION
#pragma GCC push_options
#pragma GCC optimize("fp-contract=fast")
#endif

namespace frbjax {

enum Regime { kMajor = 0, kMinor = 1, kSeparatrix = 2, kUniform = 3 };

constexpr int kMotionInputs = 7;    // J1, J2, J3, l1, l2, l3, tau
constexpr int kMotionOutputs = 11;  // L (3), q̂(0) (4), q̂(tau) (4)

// Pi(n; phi_r|m) - F(phi_r|m) for -1 <= n <= 0, Pi itself for n < -1 (|phi_r| <= pi/2, s = sin,
// c = cos >= 0): (n/3) s^3 R_J(c^2, Delta^2, 1, 1 - n s^2) (DLMF 19.25.14), and for n < -1 with
// omega = m/n, kappa = (1 - n)(1 - omega): atan2(sqrt(kappa) s, c Delta)/sqrt(kappa) - (omega/3) s^3
// R_J(c^2, Delta^2, 1, 1 - omega s^2) (DLMF 19.7.8, 19.2.18).  frbjax/special/_legendre.py's
// `pi_without_first_kind`.
template <class T>
T pi_without_first_kind(const T& n, const T& s, const T& c, const T& m, const T& mc) {
  using std::atan2;
  using std::sqrt;
  const bool transformed = value(n) < -1 && value(m) > value(n);
  const T characteristic = transformed ? m / n : n;
  const T delta_squared = c * c + mc * s * s;
  const T tail = characteristic * s * s * s * elliprj<T>(c * c, delta_squared, T(1.0), 1.0 - characteristic * s * s) / 3.0;
  if (!transformed) return tail;
  const T kappa = (1.0 - n) * (1.0 - characteristic);
  return atan2(sqrt(kappa) * s, c * sqrt(delta_squared)) * sqrt(kappa) / kappa - tail;
}

// R_J(0, mc, 1, p) for 0 < mc <= 1, p > 0.  Values: 3 cel(sqrt(mc), p, 0, 1) (DLMF 19.2.11, 19.25.2) by
// Bulirsch's iteration (R. Bulirsch, Numer. Math. 13 (1969) 305-315; the JAX path's `rj_complete`),
// a square root and a quotient per step, stopped where the quadratic convergence has reached the
// dtype's rounding (the relative gap of the means below its square root).  Dual numbers: R_J's
// duplication, whose derivatives converge to the function's.
template <class T>
T rj_complete(const T& mc, const T& p) {
  if constexpr (is_dual<T>::value) {
    return elliprj<T>(T(0.0), mc, T(1.0), p);
  } else {
    using std::fabs;
    using std::sqrt;
    const T tolerance = sizeof(T) == 8 ? T(1.0 / 134217728) : T(1.0 / 8192);  // 2^-27, 2^-13
    T kc = sqrt(mc), e = kc, mean = 1, root_p = sqrt(p);
    T a = 0, b = 1 / root_p;
    for (int step = 0; step < 40; ++step) {
      T f = a;
      a = a + b / root_p;
      T g = e / root_p;
      b = 2 * (b + f * g);
      root_p = g + root_p;
      g = mean;
      mean = mean + kc;
      if (fabs(g - kc) <= g * tolerance) break;
      kc = 2 * sqrt(e);
      e = kc * mean;
    }
    return T(3 * 1.5707963267948966) * (b + a * mean) / (mean * (mean + root_p));
  }
}

// The same over a half period (s = 1, c = 0): Pi(n|m) - K(m) or Pi(n|m), with the complete R_J
// (DLMF 19.7.8 and 19.25.14 at phi = pi/2).
template <class T>
T complete_third_kind(const T& n, const T& m, const T& mc) {
  using std::sqrt;
  const bool transformed = value(n) < -1 && value(m) > value(n);
  const T characteristic = transformed ? m / n : n;
  const T tail = characteristic * rj_complete<T>(mc, 1.0 - characteristic) / 3.0;
  if (!transformed) return tail;
  const T kappa = (1.0 - n) * (1.0 - characteristic);
  return T(1.5707963267948966) * sqrt(kappa) / kappa - tail;
}

// (sn, cn) with sn^2 + cn^2 = 1 from a common positive multiple, scaled by a power of two first where
// both are tiny or huge (both can be ~1e-222, whose squares underflow): exact, and chosen by selects,
// so that a loop over points stays vectorisable.  The larger one is then within 2^-200..2^424 (float:
// 2^-40..2^48); where the smaller one's square still underflows it is below the larger one's times
// 2^-600 (float: 2^-46), which the sum does not see.
template <class T>
FRBJAX_INLINE void unit_point(T sn_scaled, T cn_scaled, T& sn, T& cn) {
  using std::sqrt;
  constexpr bool is_double = sizeof(real_t<T>) == 8;
  const double largest = std::max(std::fabs(static_cast<double>(value(sn_scaled))),
                                  std::fabs(static_cast<double>(value(cn_scaled))));
  const double scale = largest < (is_double ? 0x1p-800 : 0x1p-100)  ? (is_double ? 0x1p1000 : 0x1p120)
                       : largest < (is_double ? 0x1p-200 : 0x1p-40) ? (is_double ? 0x1p600 : 0x1p60)
                       : largest > (is_double ? 0x1p200 : 0x1p40)   ? (is_double ? 0x1p-600 : 0x1p-80)
                                                                    : 1.0;
  sn_scaled = sn_scaled * scale;
  cn_scaled = cn_scaled * scale;
  T norm = sqrt(sn_scaled * sn_scaled + cn_scaled * cn_scaled);
  sn = sn_scaled / norm;
  cn = cn_scaled / norm;
}

// The per-body constants of the elliptic regimes (docs/theory.md §4; `_regimes.orbit_constants`): one
// set of formulas for both, with the roles of the axes exchanged.  The pivot axis p (J1; J3 in the minor
// regime) carries the chart, o (J3; J1) is the other extreme; g_p, g_o their energy gaps (computed
// without cancellation, docs/theory.md §3).  The amplitudes are those of L's components (major:
// (A1 cn, A2 sn, A3 dn), minor: (A1 dn, A2 sn, A3 cn)); (sn0, cn0) the point of the phase, from the
// ratios of the given components.
template <class T>
struct EllipticOrbit {
  T amplitude[3], rate, m, mc, alpha, nu, precession, sn0, cn0;
};

template <class T>
FRBJAX_INLINE EllipticOrbit<T> elliptic_orbit(const T j1, const T j2, const T j3, const T l1, const T l2, const T l3,
                                              bool minor) {
  // Values, not references: a select between references is one between addresses, which a loop over
  // points does not vectorise.
  using std::fabs;
  using std::sqrt;
  const T a = j2 - j1, b = j3 - j2, c = j3 - j1;
  const T g1 = l2 * l2 * a / j2 + l3 * l3 * c / j3;
  const T g3 = l1 * l1 * c / j1 + l2 * l2 * b / j2;
  const T g2 = l1 * l1 * a / j1 - l3 * l3 * b / j3;
  const T j_pivot = minor ? j3 : j1, j_other = minor ? j1 : j3;
  const T g_pivot = minor ? g3 : g1, g_other = minor ? g1 : g3;
  const T gap_pivot = minor ? a : b, gap_other = minor ? b : a;
  EllipticOrbit<T> orbit;
  const T amplitude_pivot = sqrt(j_pivot * g_other / c);
  const T amplitude_other = sqrt(j_other * g_pivot / c);
  orbit.amplitude[0] = minor ? amplitude_other : amplitude_pivot;
  orbit.amplitude[1] = sqrt(j2 * g_other / gap_pivot);
  orbit.amplitude[2] = minor ? amplitude_pivot : amplitude_other;
  orbit.rate = sqrt(g_pivot * gap_pivot / (j1 * j2 * j3));
  orbit.m = g_other * gap_other / (g_pivot * gap_pivot);
  orbit.mc = c * fabs(g2) / (g_pivot * gap_pivot);
  orbit.alpha = c / sqrt(j1 * g_pivot * gap_pivot * j3 / j2);
  orbit.nu = -j_pivot * g_other / (j_other * g_pivot);
  // alpha Pi = alpha u + alpha (Pi - F) for nu >= -1: alpha B = 1/J1 - 1/J3 turns the precession rate
  // 1/J_p into 1/J_o (`orbit_constants`).
  orbit.precession = 1.0 / (value(orbit.nu) >= -1 ? j_other : j_pivot);
  unit_point(l2 * amplitude_pivot, (minor ? l3 : l1) * orbit.amplitude[1], orbit.sn0, orbit.cn0);
  return orbit;
}

template <class T>
FRBJAX_INLINE EllipticOrbit<T> elliptic_orbit(const T* in, bool minor) {
  return elliptic_orbit(in[0], in[1], in[2], in[3], in[4], in[5], minor);
}

// The separatrix's constants (docs/theory.md §5): L = (A1 sech, tanh, A3 sech)(u), delta = alpha, and
// the phase from sinh(u0) = l2 A1/l1, which keeps its digits next to the saddle (l2 -> 1).
template <class T>
struct SeparatrixOrbit {
  T amplitude_1, amplitude_3, rate, delta, u0;
};

template <class T>
SeparatrixOrbit<T> separatrix_orbit(const T* in) {
  using std::asinh;
  using std::sqrt;
  const T &j1 = in[0], &j2 = in[1], &j3 = in[2], &l1 = in[3], &l2 = in[4];
  const T a = j2 - j1, b = j3 - j2, c = j3 - j1;
  SeparatrixOrbit<T> orbit;
  orbit.amplitude_1 = sqrt(j1 * b / (j2 * c));
  orbit.amplitude_3 = sqrt(j3 * a / (j2 * c));
  orbit.rate = sqrt(a * b / (j1 * j3)) / j2;
  orbit.delta = sqrt(j3 * a) / (sqrt(j2 * c) + sqrt(j1 * b));
  orbit.u0 = asinh(l2 * orbit.amplitude_1 / l1);
  return orbit;
}

// The motion's atan2 and (cos, sin): circular.hpp's forms on real numbers (`arctangent2_points`,
// `cos_sin_points`, which the block below calls on its points), on dual numbers the same values with
// the derivatives of dual.hpp's rules (d atan2 = (x dy - y dx)/(x^2 + y^2), d(cos, sin) = (-sin, cos) dx).
template <class T>
T motion_arctangent2(const T& y, const T& x) {
  if constexpr (is_dual<T>::value) {
    T angle = atan2(y, x);
    angle.v = motion_arctangent2(y.v, x.v);
    return angle;
  } else {
    T angle;
    circular::arctangent2_points(&y, &x, 1, &angle);
    return angle;
  }
}

template <class T>
void motion_cos_sin(const T& x, T& cosine, T& sine) {
  if constexpr (is_dual<T>::value) {
    motion_cos_sin(x.v, cosine.v, sine.v);
    for (std::size_t i = 0; i < sizeof(x.d) / sizeof(x.d[0]); ++i) {
      cosine.d[i] = -sine.v * x.d[i];
      sine.d[i] = cosine.v * x.d[i];
    }
  } else {
    circular::cos_sin_points(&x, 1, &cosine, &sine);
  }
}

// The elliptic regimes' motion in three stages, so that a block of points can take the branchy
// special functions point by point and the straight-line rest as loops the compiler vectorises
// (`working_motion_block`); `working_motion` runs the same stages at one point.
//
// 1. `elliptic_orbit` (above; straight-line code) and `elliptic_point` (branchy): (sn, cn, dn)(v) at
//    v = B tau, and the third-kind integral's change over v from its reduced point and whole
//    half-periods (DLMF 19.2.10); F is additive, so the same addition term below serves Pi - F.
template <class T>
struct EllipticPoint {
  JacobiTriple<T> at_v;
  T third_kind;
};

template <class T>
EllipticPoint<T> elliptic_point(const T& rate, const T& m, const T& mc, const T& nu, const T& tau, bool attitude) {
  EllipticPoint<T> point;
  point.at_v = jacobi_triple(rate * tau, m, mc);
  const JacobiTriple<T>& at_v = point.at_v;
  point.third_kind = T(0.0);
  if (attitude) {
    const double parity = std::fmod(std::fabs(at_v.turns), 2.0) == 1 ? -1.0 : 1.0;
    point.third_kind = pi_without_first_kind<T>(nu, parity * at_v.sn, parity * at_v.cn, m, mc);
    if (at_v.turns != 0) point.third_kind = point.third_kind + 2.0 * at_v.turns * complete_third_kind<T>(nu, m, mc);
  }
  return point;
}

// 2. `elliptic_state` (straight-line): L at u0 + v from the given l and (sn, cn, dn)(v) by DLMF
//    22.8.1-22.8.3, as increments over (sn0, cn0, dn0) for short steps (the given l exactly at tau = 0,
//    no bias over many short steps), the normalised direct form elsewhere (`evaluate_once`, where the
//    identities are written out); and the arguments (y, x) of the precession angle's two arctangents:
//    the addition term of Pi (Whittaker and Watson 22.74) and the change of atan2(L2, L_o) (L_o = L3,
//    or L1 in the minor regime, is A_o dn > 0 at both times) as one arctangent.
template <class T>
FRBJAX_INLINE void elliptic_state(const T& l1, const T& l2, const T& l3, bool minor, const T& amplitude_1,
                                  const T& amplitude_middle, const T& amplitude_3, const T& m, const T& mc,
                                  const T& nu, const T& sn0, const T& cn0, const T& sn_v, const T& cn_v,
                                  const T& dn_v, T& k1, T& k2, T& k3, T& addition_y, T& addition_x, T& angle_y,
                                  T& angle_x) {
  using std::sqrt;
  const T dn0 = sqrt(cn0 * cn0 + mc * (sn0 * sn0));
  const T sn_v_squared = sn_v * sn_v;
  const T one_minus_cn = value(cn_v) > 0 ? sn_v_squared / (1.0 + cn_v) : 1.0 - cn_v;
  const T one_minus_dn = m * sn_v_squared / (1.0 + dn_v);
  const T one_minus_dn_squared = one_minus_dn * (1.0 + dn_v);
  const T one_minus_cn_dn = one_minus_cn + cn_v * one_minus_dn;
  const T sn0_squared = sn0 * sn0;
  const T denominator = cn0 * cn0 + sn0_squared * (dn_v * dn_v);
  const bool incremental = value(denominator) >= 0.25 && value(sn_v_squared) <= 0.25;
  // Both forms, then selects: a loop over points stays straight-line code.
  const T sn_change = (cn0 * dn0 * sn_v - sn0 * (one_minus_cn_dn - sn0_squared * one_minus_dn_squared)) / denominator;
  const T cn_change = (-cn0 * (one_minus_cn - sn0_squared * one_minus_dn_squared) - sn0 * dn0 * sn_v * dn_v) / denominator;
  const T sn_direct = (sn0 * cn_v * dn_v + sn_v * cn0 * dn0) / denominator;
  const T cn_direct = (cn0 * cn_v - sn0 * dn0 * sn_v * dn_v) / denominator;
  const T norm = sqrt(sn_direct * sn_direct + cn_direct * cn_direct);
  const T sn_w = incremental ? sn0 + sn_change : sn_direct / norm;
  const T cn_w = incremental ? cn0 + cn_change : cn_direct / norm;
  const T dn_w = sqrt(cn_w * cn_w + mc * (sn_w * sn_w));
  // dn_w - dn0 with the rounding of sn_change scaled by mc (precision next to the saddle).
  const T dn_change = (cn_change * (cn_w + cn0) + mc * sn_change * (sn_w + sn0)) / (dn_w + dn0);
  k1 = incremental ? l1 + amplitude_1 * (minor ? dn_change : cn_change) : amplitude_1 * (minor ? dn_w : cn_w);
  k2 = incremental ? l2 + amplitude_middle * sn_change : amplitude_middle * sn_w;
  k3 = incremental ? l3 + amplitude_3 * (minor ? cn_change : dn_change) : amplitude_3 * (minor ? cn_w : dn_w);
  const T minus_nu = -nu;
  const T addition_scale = sqrt(minus_nu * (m + minus_nu) * (1.0 + minus_nu));
  addition_y = addition_scale * sn0 * sn_v * sn_w;
  addition_x = 1.0 + minus_nu * (sn_w * sn_w) - minus_nu * sn0 * sn_v * cn_w * dn_w;
  const T &partner = minor ? k1 : k3, &partner_start = minor ? l1 : l3;
  angle_y = k2 * partner_start - partner * l2;
  angle_x = partner * partner_start + k2 * l2;
}

// 3. `elliptic_half_angle` (straight-line): psi/2 from the two arctangents,
//    psi = tau / J_p + atan2 terms - alpha (Pi(nu; am u|m) [- u])  between 0 and tau.
template <class T>
FRBJAX_INLINE T elliptic_half_angle(const T& tau, bool minor, const T& precession, const T& alpha, const T& nu,
                                    const T& m, const T& third_kind, const T& addition_angle,
                                    const T& angle_change) {
  using std::sqrt;
  const T minus_nu = -nu;
  const T addition_amplitude = sqrt(minus_nu) / sqrt((1.0 + minus_nu) * (m + minus_nu));
  const T third_kind_change = third_kind - addition_amplitude * addition_angle;
  const T psi = precession * tau + (minor ? -1.0 : 1.0) * (angle_change - alpha * third_kind_change);
  return psi / 2.0;
}

// The separatrix's L and psi (docs/theory.md §5): L = (A1 sech, tanh, A3 sech)(u), psi = tau/J2 +
// 2 atan(delta tanh(u/2)) from u0 to u.
template <class T>
void separatrix_motion(const T* in, T& k1, T& k2, T& k3, T& psi) {
  using std::atan;
  using std::exp;
  using std::fabs;
  using std::tanh;
  const SeparatrixOrbit<T> orbit = separatrix_orbit(in);
  const T u = orbit.u0 + orbit.rate * in[6];
  const T decay = exp(-fabs(u));
  const T sech = 2.0 * decay / (1.0 + decay * decay);
  k1 = orbit.amplitude_1 * sech;
  k2 = tanh(u);
  k3 = orbit.amplitude_3 * sech;
  psi = in[6] / in[1] + 2.0 * (atan(orbit.delta * tanh(u / 2.0)) - atan(orbit.delta * tanh(orbit.u0 / 2.0)));
}

template <class T>
void working_motion(const T* in, int regime, bool attitude, T* out) {
  const T &l1 = in[3], &l2 = in[4], &l3 = in[5], &tau = in[6];
  const bool minor = regime == kMinor;
  for (int k = 0; k < kMotionOutputs; ++k) out[k] = T(0.0);
  out[3] = out[7] = T(1.0);
  if (regime == kUniform || regime < 0 || regime > kUniform) {
    out[0] = l1;
    out[1] = l2;
    out[2] = l3;
    return;
  }
  T k1, k2, k3, half_psi;
  if (regime == kSeparatrix) {
    T psi;
    separatrix_motion(in, k1, k2, k3, psi);
    half_psi = psi / 2.0;
  } else {
    const EllipticOrbit<T> orbit = elliptic_orbit(in, minor);
    const EllipticPoint<T> point = elliptic_point(orbit.rate, orbit.m, orbit.mc, orbit.nu, tau, attitude);
    T addition_y, addition_x, angle_y, angle_x;
    elliptic_state(l1, l2, l3, minor, orbit.amplitude[0], orbit.amplitude[1], orbit.amplitude[2], orbit.m,
                   orbit.mc, orbit.nu, orbit.sn0, orbit.cn0, point.at_v.sn, point.at_v.cn, point.at_v.dn, k1, k2,
                   k3, addition_y, addition_x, angle_y, angle_x);
    if (attitude)
      half_psi = elliptic_half_angle(tau, minor, orbit.precession, orbit.alpha, orbit.nu, orbit.m, point.third_kind,
                                     motion_arctangent2(addition_y, addition_x), motion_arctangent2(angle_y, angle_x));
  }
  out[0] = k1;
  out[1] = k2;
  out[2] = k3;
  if (!attitude) return;
  chart<T>(T(1.0), T(0.0), l1, l2, l3, minor, out + 3);
  T half_cos, half_sin;
  motion_cos_sin(half_psi, half_cos, half_sin);
  chart<T>(half_cos, half_sin, k1, k2, k3, minor, out + 7);
}

// Points whose motion is formed together: the straight-line stages run as loops over a block's
// points, which the compiler vectorises (series.hpp's evaluation uses the same size).
constexpr int kBlock = 32;

// The block's vectorised loops with fused products and sums run over whole vectors of points (the 32
// bytes of the widest vectors the kernels are built for, AVX), the points after the given ones
// stand-ins: every point takes the vectorised code (no scalar remainder, whose products and sums may
// fuse differently), so that a point's result does not depend on its place in the batch.  (The loops
// of free_flow.hpp fuse nothing: each operation rounds once, vectorised or not.)
template <class R>
inline int whole_lanes(int count) {
  constexpr int lanes = 32 / sizeof(R);
  return (count + lanes - 1) / lanes * lanes;
}

// The inputs of a block's lanes after `count` up to `whole_lanes`, which its vectorised stages read:
// a body (1, 2, 3) spinning about its first axis, which no result takes.
template <class R>
void fill_stand_ins(R (&in)[kMotionInputs][kBlock], int count) {
  for (int i = count; i < whole_lanes<R>(count); ++i)
    for (int k = 0; k < kMotionInputs; ++k) in[k][i] = k < 3 ? R(k + 1) : R(k == 3);
}

// `working_motion` at up to kBlock points of real numbers: in[input][point] (`fill_stand_ins` after
// `count`), regime[point], out[output][point].  The elliptic points take `elliptic_point` one by one,
// then each straight-line stage as one loop over the block's lanes (`whole_lanes`), and the
// arctangents, cosine and sine as circular.hpp's `arctangent2_points` and `cos_sin_points`.  Other
// regimes take `working_motion` itself.
template <class R, bool Attitude>
void working_motion_block(const R (&in)[kMotionInputs][kBlock], const int* regime, int count,
                          R (&out)[kMotionOutputs][kBlock]) {
  const int lanes = whole_lanes<R>(count);
  // Stage 1: the orbit's constants over the block (vectorised without `omp simd`, which GCC 12 does
  // not apply to a loop with a local array), then the special functions point by point (stand-ins
  // elsewhere).
  R minor[kBlock], amplitude_1[kBlock], amplitude_middle[kBlock], amplitude_3[kBlock], rate[kBlock], m[kBlock];
  R mc[kBlock], nu[kBlock], alpha[kBlock], precession[kBlock], sn0[kBlock], cn0[kBlock];
  bool elliptic[kBlock];
  for (int i = 0; i < lanes; ++i) {
    elliptic[i] = i < count && (regime[i] == kMajor || regime[i] == kMinor);
    minor[i] = i < count && regime[i] == kMinor ? R(1) : R(0);
  }
  for (int i = 0; i < lanes; ++i) {
    const EllipticOrbit<R> orbit = elliptic_orbit(in[0][i], in[1][i], in[2][i], in[3][i], in[4][i], in[5][i], minor[i] != 0);
    amplitude_1[i] = orbit.amplitude[0], amplitude_middle[i] = orbit.amplitude[1], amplitude_3[i] = orbit.amplitude[2];
    rate[i] = orbit.rate, m[i] = orbit.m, mc[i] = orbit.mc, nu[i] = orbit.nu, alpha[i] = orbit.alpha;
    precession[i] = orbit.precession, sn0[i] = orbit.sn0, cn0[i] = orbit.cn0;
  }
  R sn_v[kBlock], cn_v[kBlock], dn_v[kBlock], third_kind[kBlock];
  for (int i = 0; i < lanes; ++i) {
    if (!elliptic[i]) {
      // A stand-in point on a regular orbit (m = 1/2 at v = 0), which no result takes.
      minor[i] = 0, amplitude_1[i] = amplitude_middle[i] = amplitude_3[i] = 1, m[i] = mc[i] = 0.5;
      nu[i] = -0.5, alpha[i] = precession[i] = 1, sn0[i] = 0, cn0[i] = 1, sn_v[i] = 0, cn_v[i] = dn_v[i] = 1;
      third_kind[i] = 0;
      continue;
    }
    const EllipticPoint<R> point = elliptic_point(rate[i], m[i], mc[i], nu[i], in[6][i], Attitude);
    sn_v[i] = point.at_v.sn, cn_v[i] = point.at_v.cn, dn_v[i] = point.at_v.dn;
    third_kind[i] = point.third_kind;
  }
  // Stage 2 over the block.
  R k1[kBlock], k2[kBlock], k3[kBlock], addition_y[kBlock], addition_x[kBlock], angle_y[kBlock], angle_x[kBlock];
  R l1[kBlock], l2[kBlock], l3[kBlock];
  for (int i = 0; i < lanes; ++i) {
    l1[i] = elliptic[i] ? in[3][i] : R(1);
    l2[i] = elliptic[i] ? in[4][i] : R(0);
    l3[i] = elliptic[i] ? in[5][i] : R(0);
  }
#pragma omp simd
  for (int i = 0; i < lanes; ++i)
    elliptic_state<R>(l1[i], l2[i], l3[i], minor[i] != 0, amplitude_1[i], amplitude_middle[i], amplitude_3[i], m[i],
                      mc[i], nu[i], sn0[i], cn0[i], sn_v[i], cn_v[i], dn_v[i], k1[i], k2[i], k3[i], addition_y[i],
                      addition_x[i], angle_y[i], angle_x[i]);
  if constexpr (Attitude) {
    R addition_angle[kBlock], angle_change[kBlock], half_psi[kBlock];
    // (The addition term's arguments overflow in float32 next to the plane of a symmetric body's
    // equal moments, nu ~ -1e24: the C library's atan2 there.)
    circular::arctangent2_points(addition_y, addition_x, lanes, addition_angle);
    circular::arctangent2_points(angle_y, angle_x, lanes, angle_change);
    // Stage 3 over the block.
#pragma omp simd
    for (int i = 0; i < lanes; ++i)
      half_psi[i] = elliptic_half_angle<R>(in[6][i], minor[i] != 0, precession[i], alpha[i], nu[i], m[i],
                                           third_kind[i], addition_angle[i], angle_change[i]);
    R half_cos[kBlock], half_sin[kBlock];
    circular::cos_sin_points(half_psi, lanes, half_cos, half_sin);
    // The charts q̂(0) and q̂(tau) (vectorised without `omp simd`, which GCC 12 does not apply to a
    // loop with a local array).
    for (int i = 0; i < lanes; ++i) {
      const bool is_minor = minor[i] != 0;
      R start[4], now[4];
      chart<R>(R(1), R(0), l1[i], l2[i], l3[i], is_minor, start);
      chart<R>(half_cos[i], half_sin[i], k1[i], k2[i], k3[i], is_minor, now);
      for (int k = 0; k < 4; ++k) {
        out[3 + k][i] = start[k];
        out[7 + k][i] = now[k];
      }
    }
  }
  for (int i = 0; i < lanes; ++i) {
    out[0][i] = k1[i];
    out[1][i] = k2[i];
    out[2][i] = k3[i];
  }
  // The other regimes (the separatrix, uniform rotation) point by point.
  for (int i = 0; i < count; ++i) {
    if (elliptic[i]) continue;
    R point_in[kMotionInputs], values[kMotionOutputs];
    for (int k = 0; k < kMotionInputs; ++k) point_in[k] = in[k][i];
    working_motion<R>(point_in, regime[i], Attitude, values);
    for (int k = 0; k < (Attitude ? kMotionOutputs : 3); ++k) out[k][i] = values[k];
  }
}

}  // namespace frbjax

#ifdef FRBJAX_FUSED_MOTION
#pragma GCC pop_options
#endif
