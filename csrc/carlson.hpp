// Carlson's symmetric elliptic integrals R_F, R_D, R_J, R_C for real arguments (DLMF 19.16), one
// scalar implementation templated on the number type (float, double, and the dual numbers of
// dual.hpp for their partial derivatives).  The algorithms are the JAX path's
// (frbjax/special/_carlson.py), with a per-point loop that stops at the point's own convergence:
//
// * R_F, R_D, R_J: Carlson's duplication (B. C. Carlson, Numer. Algorithms 10 (1995) 13-26;
//   DLMF 19.36.1-19.36.2): steps until the relative spread 4^-k Q / A_k is at most 2^-8 (float64;
//   2^-5 in float32), at most 12 (7) steps, then the Taylor series through seventh order.  Dual numbers
//   take every step (their series converge a power of the spread more slowly).
// * R_J's step carries R_C(1, 1 + e_k) (Carlson 1995, eq. (2.19)), with 1 + e_k computed without
//   cancellation when e_k -> -1, R_C's polynomial taken at e_k directly where |e_k| <= 0.1716 (the JAX
//   path takes one duplication step of R_C first at every step: the same function to rounding); for
//   p much larger than x, y, z, DLMF 19.21.12 trades p for a parameter close to the largest argument.
// * R_C: its closed forms (DLMF 19.2.18-19.2.19), a series near x = y, the principal value for y < 0
//   (DLMF 19.6.16).
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "dual.hpp"

namespace frbjax {

template <class T>
struct Duplication {
  int steps;
  double threshold;
};

template <class T>
inline Duplication<T> duplication_plan() {
  if (sizeof(real_t<T>) == 8) return {12, 1.0 / 256};
  return {7, 1.0 / 32};
}

// Whether the loop may stop at convergence (values) or takes every step (derivatives).
template <class T>
inline bool stops_early() {
  return !is_dual<T>::value;
}

template <class T>
inline double magnitude(const T& x) {
  return std::fabs(static_cast<double>(value(x)));
}

template <class T>
inline T rf_polynomial(const T& big_x, const T& big_y) {
  // DLMF 19.36.1 through seventh order, X + Y + Z = 0.
  T big_z = -(big_x + big_y);
  T e2 = big_x * big_y - big_z * big_z;
  T e3 = big_x * big_y * big_z;
  return 1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0 - 5.0 * e2 * e2 * e2 / 208.0 +
         3.0 * e3 * e3 / 104.0 + e2 * e2 * e3 / 16.0;
}

template <class T>
inline T rj_polynomial(const T& e2, const T& e3, const T& e4, const T& e5) {
  // DLMF 19.36.2 (Carlson 1995, eq. (2.7)), through seventh order.
  return 1.0 - 3.0 * e2 / 14.0 + e3 / 6.0 + 9.0 * e2 * e2 / 88.0 - 3.0 * e4 / 22.0 - 9.0 * e2 * e3 / 52.0 +
         3.0 * e5 / 26.0 - e2 * e2 * e2 / 16.0 + 3.0 * e3 * e3 / 40.0 + 3.0 * e2 * e4 / 20.0 +
         45.0 * e2 * e2 * e3 / 272.0 - 9.0 * (e3 * e4 + e2 * e5) / 68.0;
}

template <class T>
T elliprf(T x, T y, T z) {
  using std::sqrt;
  const Duplication<T> plan = duplication_plan<T>();
  T mean = (x + y + z) / 3.0;
  T dx0 = mean - x, dy0 = mean - y;
  double spread = std::max({magnitude(dx0), magnitude(dy0), magnitude(mean - z)});
  double quarter = 1;
  for (int k = 0; k < plan.steps; ++k) {
    if (stops_early<T>() && quarter * spread <= plan.threshold * static_cast<double>(value(mean))) break;
    T sx = sqrt(x), sy = sqrt(y), sz = sqrt(z);
    T lambda = sx * (sy + sz) + sy * sz;
    x = (x + lambda) / 4.0;
    y = (y + lambda) / 4.0;
    z = (z + lambda) / 4.0;
    mean = (mean + lambda) / 4.0;
    quarter /= 4;
  }
  // X = 1 - x_N/A_N without cancellation: (A_0 - x_0) / (4^N A_N).
  T scale = quarter / mean;
  return rf_polynomial(dx0 * scale, dy0 * scale) / sqrt(mean);
}

template <class T>
T elliprd(T x, T y, T z) {
  using std::sqrt;
  const Duplication<T> plan = duplication_plan<T>();
  T mean = (x + y + 3.0 * z) / 5.0;
  T dx0 = mean - x, dy0 = mean - y;
  double spread = std::max({magnitude(dx0), magnitude(dy0), magnitude(mean - z)});
  double quarter = 1;
  T correction(0.0);
  for (int k = 0; k < plan.steps; ++k) {
    if (stops_early<T>() && quarter * spread <= plan.threshold * static_cast<double>(value(mean))) break;
    T sx = sqrt(x), sy = sqrt(y), sz = sqrt(z);
    T lambda = sx * (sy + sz) + sy * sz;
    correction = correction + quarter / (sz * (z + lambda));
    x = (x + lambda) / 4.0;
    y = (y + lambda) / 4.0;
    z = (z + lambda) / 4.0;
    mean = (mean + lambda) / 4.0;
    quarter /= 4;
  }
  T scale = quarter / mean;
  T big_x = dx0 * scale, big_y = dy0 * scale;
  T big_z = -(big_x + big_y) / 3.0;
  // R_D = R_J(x, y, z, z): the R_J series with P = Z.
  T xy = big_x * big_y, z2 = big_z * big_z;
  T e2 = xy - 6.0 * z2;
  T e3 = (3.0 * xy - 8.0 * z2) * big_z;
  T e4 = 3.0 * (xy - z2) * z2;
  T e5 = xy * z2 * big_z;
  return quarter * rj_polynomial(e2, e3, e4, e5) / (mean * sqrt(mean)) + 3.0 * correction;
}

// R_C(1, 1 + e) = 2F1(1/2, 1; 3/2; -e) for |e| <= 0.1716: a degree-15 Chebyshev interpolant (mpmath),
// error 7e-19, highest degree first.
constexpr double kRcPolynomial[16] = {
    -0.035845454157110504, 0.0382860515301367,  -0.036861807914879065, 0.03981424818905601,
    -0.043482670645682224, 0.04762372192420984, -0.052631517733447486, 0.05882346452803347,
    -0.0666666671270696,   0.07692307741107116, -0.09090909090739277,  0.11111111110931124,
    -0.14285714285714524,  0.20000000000000254, -0.3333333333333333,   1.0,
};

// Estrin's scheme, not Horner's rule: R_J takes it at each of its duplication steps, and the
// products of a 15-deep Horner chain wait on each other (depth 4 here); the rounding is as small.
template <class T>
inline T rc_polynomial(const T& x) {
  const T x2 = x * x, x4 = x2 * x2;
  T pairs[8];
  for (int k = 0; k < 8; ++k) pairs[k] = kRcPolynomial[2 * k] * x + kRcPolynomial[2 * k + 1];
  T quads[4];
  for (int k = 0; k < 4; ++k) quads[k] = pairs[2 * k] * x2 + pairs[2 * k + 1];
  return (quads[0] * x4 + quads[1]) * (x4 * x4) + (quads[2] * x4 + quads[3]);
}

// R_C(1, w) for 0 < w <= 2, w given accurately (w = 1 + e_k in R_J's step).
template <class T>
inline T rc_one_plus(const T& w) {
  using std::log;
  using std::sqrt;
  if (value(w) < 0.5) {
    // artanh(r)/r with r = sqrt(1 - w), as log((1 + r)^2/w) / (2r): no cancellation as w -> 0.
    T root = sqrt(1.0 - w);
    return log((1.0 + root) * (1.0 + root) / w) / (2.0 * root);
  }
  // One duplication step of R_C itself, then the polynomial: with a = sqrt(w),
  // R_C(1, w) = 2/(1 + a) R_C(1, 1 + (a - 1)/(a + 1)).
  T a = sqrt(w);
  T inverse = 1.0 / (1.0 + a);
  return 2.0 * rc_polynomial((a - 1.0) * inverse) * inverse;
}

// R_J(x, y, z, p) for p > 0 by the duplication (Carlson 1995, eqs. (2.3)-(2.7), (2.19)).
template <class T>
T rj_duplication(T x, T y, T z, T p) {
  using std::sqrt;
  const Duplication<T> plan = duplication_plan<T>();
  T mean = (x + y + z + 2.0 * p) / 5.0;
  T dx0 = mean - x, dy0 = mean - y, dz0 = mean - z;
  T px0 = p - x, py0 = p - y, pz0 = p - z;
  double spread = std::max({magnitude(dx0), magnitude(dy0), magnitude(dz0), magnitude(mean - p)});
  // e_k < 0 (an odd number of arguments above p) is decided by the inputs alone.
  bool negative = (value(px0) < 0) ^ (value(py0) < 0) ^ (value(pz0) < 0);
  double quarter = 1;
  T correction(0.0);
  for (int k = 0; k < plan.steps; ++k) {
    if (stops_early<T>() && quarter * spread <= plan.threshold * static_cast<double>(value(mean))) break;
    T sx = sqrt(x), sy = sqrt(y), sz = sqrt(z), sp = sqrt(p);
    T lambda = sx * (sy + sz) + sy * sz;
    T ix = 1.0 / (sp + sx), iy = 1.0 / (sp + sy), iz = 1.0 / (sp + sz);
    // e_k = 4^{-3k} (p-x)(p-y)(p-z) / d_k^2 as a product of three ratios in (-1, 1), each from the
    // exact difference 4^-k (p_0 - x_0) = p_k - x_k: nothing overflows or cancels.
    T w;
    if (negative) {
      // 1 + e_k = 1 - prod(1 - t_j), t_j = 2 min(sqrt p, sqrt x_j)/(sqrt p + sqrt x_j), no subtraction.
      T tx = 2.0 * (value(sp) < value(sx) ? sp : sx) * ix;
      T ty = 2.0 * (value(sp) < value(sy) ? sp : sy) * iy;
      T tz = 2.0 * (value(sp) < value(sz) ? sp : sz) * iz;
      w = tx + ty + tz - (tx * ty + tx * tz + ty * tz) + tx * ty * tz;
    } else {
      w = 1.0 + (quarter * px0 * ix * ix) * (quarter * py0 * iy * iy) * (quarter * pz0 * iz * iz);
    }
    // After the first steps |e_k| <= 0.1716 (e_k shrinks by about 4^-3 a step): R_C's polynomial takes
    // e_k = w - 1 (exact for w in [1/2, 2]) at once, without rc_one_plus's own duplication step.
    const T e = w - 1.0;
    const T rc = magnitude(e) <= 0.1716 ? rc_polynomial(e) : rc_one_plus(w);
    correction = correction + quarter * rc * (ix * iy * iz);
    x = (x + lambda) / 4.0;
    y = (y + lambda) / 4.0;
    z = (z + lambda) / 4.0;
    p = (p + lambda) / 4.0;
    mean = (mean + lambda) / 4.0;
    quarter /= 4;
  }
  T scale = quarter / mean;
  T big_x = dx0 * scale, big_y = dy0 * scale, big_z = dz0 * scale;
  T big_p = -(big_x + big_y + big_z) / 2.0;
  T p2 = big_p * big_p;
  T xyz = big_x * big_y * big_z;
  T e2 = big_x * big_y + big_x * big_z + big_y * big_z - 3.0 * p2;
  T e3 = xyz + 2.0 * e2 * big_p + 4.0 * p2 * big_p;
  T e4 = (2.0 * xyz + e2 * big_p + 3.0 * p2 * big_p) * big_p;
  T e5 = xyz * p2;
  return quarter * rj_polynomial(e2, e3, e4, e5) / (mean * sqrt(mean)) + 6.0 * correction;
}

// Above this ratio p / max(x, y, z) the duplication would need many more steps; DLMF 19.21.12 then
// trades p for a parameter q close to max(x, y, z).
constexpr double kLargeParameterRatio = 16.0;

template <class T>
T elliprj(T x, T y, T z, T p) {
  using std::atan;
  using std::sqrt;
  if (!(value(p) > 0)) return T(std::numeric_limits<double>::quiet_NaN());
  // The arguments in increasing order (of their values).
  T low = x, middle = y, high = z;
  if (value(low) > value(middle)) std::swap(low, middle);
  if (value(middle) > value(high)) std::swap(middle, high);
  if (value(low) > value(middle)) std::swap(low, middle);
  if (!(value(p) > kLargeParameterRatio * value(high))) return rj_duplication(x, y, z, p);
  // DLMF 19.21.12 with the largest argument as pivot:
  //   (p - z) R_J(x, y, z, p) + (q - z) R_J(x, y, z, q) = 3 R_F(x, y, z) - 3 R_C(xy/z, pq/z),
  //   (p - z)(q - z) = (x - z)(y - z); every term is positive, nothing cancels.
  T q_minus_high = (low - high) / (p - high) * (middle - high);
  T q = high + q_minus_high;
  // R_C(a, b) scaled by the largest argument (homogeneous of degree -1/2), b > a: an arctangent.
  T a = (low / high) * (middle / high);
  T b = (p / high) * (q / high);
  T rc = value(a) > 0 ? atan(sqrt((b - a) / a)) / sqrt((b - a) * high)
                      : T(1.5707963267948966) / sqrt(b * high);
  return (3.0 * elliprf(low, middle, high) - 3.0 * rc - q_minus_high * rj_duplication(low, middle, high, q)) /
         (p - high);
}

// R_C(x, y) for x >= 0, y > 0: the closed forms (DLMF 19.2.18-19.2.19), a series near x = y.
template <class T>
T rc_positive(const T& x, const T& y) {
  using std::atan;
  using std::log1p;
  using std::sqrt;
  // Derivatives: those of R_F(x, y, y) (DLMF 19.2.17), whose duplication differentiates accurately;
  // the closed forms' derivatives cancel near x = y.
  if constexpr (is_dual<T>::value) return elliprf(x, y, y);
  T difference = y - x;
  if (value(x) > 0) {
    T e = difference / x;
    if (std::fabs(static_cast<double>(value(e))) < 1.0 / 1024) {
      // x^(-1/2) sum_k (-e)^k/(2k + 1).
      T series = 1.0 + e * (-1.0 / 3 + e * (1.0 / 5 + e * (-1.0 / 7 + e * (1.0 / 9 + e * (-1.0 / 11 +
                 e * (1.0 / 13 + e * (-1.0 / 15)))))));
      return series / sqrt(x);
    }
  }
  if (value(difference) > 0) {
    T root = sqrt(difference);
    if (!(value(x) > 0)) return T(1.5707963267948966) / root;
    return atan(sqrt(difference / x)) / root;
  }
  // x > y: log((sqrt x + sqrt(x - y))/sqrt y)/sqrt(x - y), the log1p argument without cancellation.
  T magnitude_ = -difference;
  T root = sqrt(magnitude_);
  T sx = sqrt(x), sy = sqrt(y);
  return log1p((root + magnitude_ / (sx + sy)) / sy) / root;
}

template <class T>
T elliprc(T x, T y) {
  using std::sqrt;
  if (!(value(x) >= 0)) return T(std::numeric_limits<double>::quiet_NaN());
  if (value(y) > 0) return rc_positive(x, y);
  // The Cauchy principal value (DLMF 19.6.16).
  return sqrt(x / (x - y)) * rc_positive(x - y, -y);
}

}  // namespace frbjax
