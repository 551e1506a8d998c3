// Jacobi's elliptic functions sn, cn, dn and the amplitude am (DLMF 22.2, 22.16.1): the JAX path's
// algorithm (frbjax/special/_jacobi.py) per point, with its own number of AGM levels.
//
// 1. u = 2jK + u_r, |u_r| <= K, with K from the complement (complete_first), so that
//    the reduction error grows only linearly with the number of periods (DLMF 22.4.3: sn and cn change
//    sign, dn does not, am gains j pi).
// 2. For |u_r| <= K/2, Bulirsch's form of the descending Landen transformation (R. Bulirsch, Numer.
//    Math. 7 (1965) 78-90; DLMF 22.20.ii), carrying cn/sn and dn down the AGM levels with positive
//    products and sums only; for K/2 < |u_r| <= K the quarter-period reflection u_r = K - w (DLMF
//    22.4.3), so that cn and dn keep their relative precision where they are as small as sqrt(mc).
// 3. am = j pi + atan(sn_r / cn_r).
// m = 1 (mc = 0): sn = tanh u, cn = dn = sech u, am = gd u (DLMF 22.5.ii).  m > 1: NaN.
#pragma once

#include <cmath>
#include <limits>

#include "carlson.hpp"
#include "circular.hpp"

namespace frbjax {

template <class R>
struct JacobiValues {
  R sn, cn, dn, am;
  R turns;  // j of u = 2jK + u_r (0 at m = 1)
};

// K(m) = P(mc) - log(mc) Q(mc) on 0 < mc <= 1: the degree-10 fits of the JAX path
// (frbjax/special/_legendre.py, relative error 1.7e-18 against mpmath; the form of Cephes' ellpk,
// DLMF 19.12.1), and K(m) = mc^(-1/2) K(1 - 1/mc) for mc > 1 (DLMF 19.7.2).  More accurate than
// R_F(0, mc, 1) near m = 1, where the reduction of u by whole periods multiplies K's error.
constexpr double kKP[11] = {0.00012199461596300885, 0.0021024603629293606, 0.00770204240322226, 0.009983367158858069, 0.007129239803926991, 0.006267695510139254, 0.008798172870398203, 0.014938254688341316, 0.03088514797866006, 0.09657359028256746, 1.3862943611198906};
constexpr double kKQ[11] = {2.581298904233637e-05, 0.0008310182798070543, 0.0055946884717961946, 0.01504654773623327, 0.023707330763035973, 0.030085270466142393, 0.03737518215400317, 0.04882798830423169, 0.07031249945926299, 0.12499999999971124, 0.5};

template <class R>
R complete_first(R mc) {
  using std::log;
  using std::sqrt;
  bool above = mc > 1;
  R p = above ? 1 / mc : mc;
  R log_p = above ? -log(mc) : log(mc);
  R big_p = R(kKP[0]), big_q = R(kKQ[0]);
  for (int k = 1; k < 11; ++k) {
    big_p = big_p * p + R(kKP[k]);
    big_q = big_q * p + R(kKQ[k]);
  }
  R value = big_p - log_p * big_q;
  return above ? value / sqrt(mc) : value;
}

// `Amplitude`: whether am is computed (an arctangent; the motion takes sn, cn and dn alone).
template <class R, bool Amplitude = true>
JacobiValues<R> ellipj(R u, R m, R mc) {
  using std::atan;
  using std::exp;
  using std::fabs;
  using std::sqrt;
  using std::tanh;
  const bool is_double = sizeof(R) == 8;
  const R nan = std::numeric_limits<R>::quiet_NaN();
  const R pi = R(3.141592653589793);
  if (!(mc >= 0) || std::isnan(u) || std::isnan(m)) return {nan, nan, nan, nan, nan};
  if (mc == 0) {
    // sech u = 2e/(1 + e^2) with e = exp(-|u|): no overflow.
    R decay = exp(-fabs(u));
    R sech = 2 * decay / (1 + decay * decay);
    R sn = tanh(u);
    if (!Amplitude) return {sn, sech, sech, R(0), R(0)};
    return {sn, sech, sech, sech > 0 ? atan(sn / sech) : std::copysign(pi / 2, sn), R(0)};
  }
  const int max_levels = is_double ? 13 : 8;
  const R tolerance = is_double ? R(1.0 / 67108864) : R(1.0 / 4096);  // 2^-26, 2^-12
  const R tiny = is_double ? R(1e-100) : R(1e-15);
  const R quarter = complete_first(mc);
  R turns = std::nearbyint(u / (2 * quarter));
  R reduced = u - 2 * quarter * turns;
  R magnitude = fabs(reduced);
  bool upper = magnitude > quarter / 2;
  R w = upper ? quarter - magnitude : magnitude;

  // The AGM levels of DLMF 22.20.1 up to the first whose relative gap is below the tolerance; the
  // top mean is the next a (the AGM to rounding).
  R a[16], b[16];
  int levels = 0;
  R mean = 1, a_n = 1, b_n = sqrt(mc);
  while (levels < max_levels) {
    a[levels] = a_n;
    b[levels] = b_n;
    ++levels;
    R next = (a_n + b_n) / 2;
    mean = next;
    if (fabs(a_n - b_n) <= tolerance * a_n) break;
    b_n = sqrt(a_n * b_n);
    a_n = next;
  }

  R sn_w, cn_w, dn_w;
  if (w < tiny) {
    sn_w = w;
    cn_w = 1;
    dn_w = 1;
  } else {
    R theta = mean * w;  // <= pi/4
    R cos_theta, sin_theta;
    circular::cos_sin_small(theta, cos_theta, sin_theta);  // the JAX path's polynomials
    R ratio = cos_theta / sin_theta;
    R cot_ratio = mean * ratio, dn = 1;
    for (int n = levels - 1; n >= 0; --n) {
      R ratio_next = ratio * cot_ratio;
      R cot_next = cot_ratio * dn;
      dn = (b[n] + ratio_next) / (a[n] + ratio_next);
      ratio = cot_next / a[n];
      cot_ratio = cot_next;
    }
    sn_w = 1 / sqrt(cot_ratio * cot_ratio + 1);
    cn_w = cot_ratio * sn_w;
    dn_w = dn;
  }
  R root_mc = sqrt(mc);
  R sn_abs = sn_w, cn_reduced = cn_w, dn = dn_w;
  if (upper) {
    // sn = cd(w), cn = sqrt(mc) sd(w), dn = sqrt(mc) nd(w), normalised so that sn^2 + cn^2 = 1.
    R norm = sqrt(cn_w * cn_w + (root_mc * sn_w) * (root_mc * sn_w));
    sn_abs = cn_w / norm;
    cn_reduced = root_mc * sn_w / norm;
    dn = root_mc / dn_w;
  }
  R sn_reduced = reduced < 0 ? -sn_abs : sn_abs;
  R sign = std::fmod(fabs(turns), R(2)) == 1 ? R(-1) : R(1);
  if (!Amplitude) return {sign * sn_reduced, sign * cn_reduced, dn, R(0), turns};
  R angle = cn_reduced > 0 ? atan(sn_reduced / cn_reduced) : std::copysign(pi / 2, sn_reduced);
  return {sign * sn_reduced, sign * cn_reduced, dn, turns * pi + angle, turns};
}

// sn, cn, dn and the number of half periods j on any number type: on dual numbers the values of
// the level below and their partial derivatives in closed form (the JAX path's rule,
// frbjax/special/_jacobi.py): with the parameter's change dp = (dm - dmc)/2,
//   d am = dn du - dn (2j dK/dm + (sn_r^3/6) R_D(cn_r^2, 1, dn^2)) dp,  dK/dm = R_D(0, 1, mc)/6,
//   d sn = cn d am,  d cn = -sn d am,  d dn = -(sn^2 dp + 2 m sn cn d am)/(2 dn)
// (sn_r, cn_r those of the reduced argument, DLMF 22.4.3); at m = 1 the limits of DLMF 22.10.ii.
template <class T>
struct JacobiTriple {
  T sn, cn, dn;
  double turns;
};

template <class R>
JacobiTriple<R> jacobi_triple(const R& u, const R& m, const R& mc) {
  JacobiValues<R> values = ellipj<R, false>(u, m, mc);
  return {values.sn, values.cn, values.dn, static_cast<double>(values.turns)};
}

template <class T, int N>
JacobiTriple<Dual<T, N>> jacobi_triple(const Dual<T, N>& u, const Dual<T, N>& m, const Dual<T, N>& mc) {
  using std::cosh;
  using std::sinh;
  using std::tanh;
  JacobiTriple<T> base = jacobi_triple(u.v, m.v, mc.v);
  const T &sn = base.sn, &cn = base.cn, &dn = base.dn;
  T am_per_param, dn_per_param, dn_per_am;
  if (value(mc.v) == 0) {
    // The m-derivatives at m = 1 grow like e^|u|/8: |u| capped where sinh would overflow.
    T capped = value(u.v) > 700 ? T(700.0) : value(u.v) < -700 ? T(-700.0) : u.v;
    am_per_param = -(sinh(capped) - capped / cosh(capped)) / 4.0;
    dn_per_param = -tanh(capped) * (sinh(capped) + capped / cosh(capped)) / 4.0;
    dn_per_am = T(0.0);
  } else {
    const double parity = std::fmod(std::fabs(base.turns), 2.0) == 1 ? -1.0 : 1.0;
    T sn_reduced = parity * sn, cn_reduced = parity * cn;
    T amplitude_per_u = sn_reduced * sn_reduced * sn_reduced * elliprd(cn_reduced * cn_reduced, T(1.0), dn * dn) / 6.0;
    if (base.turns != 0) amplitude_per_u = amplitude_per_u + 2.0 * base.turns * elliprd(T(0.0), T(1.0), mc.v) / 6.0;
    am_per_param = -dn * amplitude_per_u;
    dn_per_param = -(sn * sn) / (2.0 * dn);
    dn_per_am = -(m.v * sn * cn) / dn;
  }
  JacobiTriple<Dual<T, N>> out;
  out.turns = base.turns;
  out.sn.v = sn;
  out.cn.v = cn;
  out.dn.v = dn;
  for (int i = 0; i < N; ++i) {
    T param = 0.5 * (m.d[i] - mc.d[i]);
    T am = dn * u.d[i] + am_per_param * param;
    out.sn.d[i] = cn * am;
    out.cn.d[i] = -sn * am;
    if (value(mc.v) == 0)
      out.dn.d[i] = -(m.v * sn * cn) * u.d[i] + dn_per_param * param;
    else
      out.dn.d[i] = dn_per_param * param + dn_per_am * am;
  }
  return out;
}

}  // namespace frbjax
