// Cosine, sine and the two-argument arctangent as straight-line code (products, sums, one quotient and
// selects), so that a loop over points that calls them is vectorised by the compiler; the C library's
// `sincos` and `atan2` are scalar calls, which took 40% of a body's series evaluation.  The
// algorithms are those of frbjax/special/_circular.py (the JAX path's cosine and sine) and of its
// earlier arctangent:
//
// * cos_sin: the argument reduced by the nearest multiple of pi/2 (Cody and Waite's three-part pi/2,
//   the first two parts short enough that their products with the multiple are exact, the reduced
//   argument carried with its rounding error), then the Taylor series of DLMF 4.19.1 and 4.19.2 on
//   [-pi/4, pi/4] and the quadrant's signs and swap.  |x| <= 2^19 pi/2 (`reduces`); beyond, the
//   caller takes the library's functions.
// * arctangent2: the quotient a of the smaller and the larger magnitude moved next to 0 by
//   arctan a = arctan c + arctan((a - c)/(1 + a c)) (DLMF 4.24.15) with c = 0, 1/4, 1/2 or 1 by
//   interval (the differences exact by Sterbenz's lemma), the quotient's roundings carried (TwoSum,
//   Dekker's product), the Taylor series of DLMF 4.24.3 for |t| <= 3/16, and the octant's angle as a
//   two-part constant to which the small arctan t is added.  Finite arguments (the motion's are).
//
// Both are float64 computations; float32 arguments are evaluated in float64 and rounded once.
// Measured against mpmath at 40 digits (2026-11-29; 11000 arguments up to 8e5 and next to multiples
// of pi/2, 8400 points over magnitudes 1e-150 to 1e150 and next to the interval ends): cos_sin at
// most 0.70 ulp (the C library's 0.51), arctangent2 at most 0.51 ulp (the C library's 0.74).  The
// series kernel that uses them is tested against the JAX series and mpmath (tests/test_compiled_motion.py,
// tests/test_body_mpmath.py).
#pragma once

#include <cmath>

// Inlined whatever their size: a loop over points that calls them is vectorised only so.
#if defined(__GNUC__)
#define FRBJAX_INLINE inline __attribute__((always_inline))
#define FRBJAX_NOINLINE __attribute__((noinline))
#else
#define FRBJAX_INLINE inline
#define FRBJAX_NOINLINE
#endif

namespace frbjax {
namespace circular {

// (a + b rounded, its exact rounding error) (Knuth's TwoSum).
FRBJAX_INLINE void two_sum(double a, double b, double& total, double& error) {
  total = a + b;
  const double b_virtual = total - a;
  const double a_virtual = total - b_virtual;
  error = (a - a_virtual) + (b - b_virtual);
}

// (a b rounded, its exact rounding error) (Dekker's product with Veltkamp's split; |a|, |b| < 2^900).
FRBJAX_INLINE void two_product(double a, double b, double& product, double& error) {
  constexpr double splitter = 134217729.0;  // 2^27 + 1
  product = a * b;
  const double a_big = splitter * a, b_big = splitter * b;
  const double a_high = a_big - (a_big - a), b_high = b_big - (b_big - b);
  const double a_low = a - a_high, b_low = b - b_high;
  error = ((a_high * b_high - product) + a_high * b_low + a_low * b_high) + a_low * b_low;
}

// Horner's rule, highest coefficient first.
template <int N>
FRBJAX_INLINE double horner(const double (&coefficients)[N], double x) {
  double sum = coefficients[0];
  for (int k = 1; k < N; ++k) sum = sum * x + coefficients[k];
  return sum;
}

// Taylor tails: sin r = r + r^3 S(r^2) through r^19, cos r = 1 - r^2/2 + r^4 C(r^2) through r^20
// ((-1)^k / (2k+1)! for k = 9 .. 1 and (-1)^k / (2k)! for k = 10 .. 2; |r| <= pi/4: first omitted
// terms below 1e-21).
constexpr double kSinTail[9] = {-1.0 / 121645100408832000.0, 1.0 / 355687428096000.0, -1.0 / 1307674368000.0,
                                1.0 / 6227020800.0,          -1.0 / 39916800.0,        1.0 / 362880.0,
                                -1.0 / 5040.0,               1.0 / 120.0,              -1.0 / 6.0};
constexpr double kCosTail[9] = {1.0 / 2432902008176640000.0, -1.0 / 6402373705728000.0, 1.0 / 20922789888000.0,
                                -1.0 / 87178291200.0,        1.0 / 479001600.0,         -1.0 / 3628800.0,
                                1.0 / 40320.0,               -1.0 / 720.0,              1.0 / 24.0};
// arctan t = t + t^3 A(t^2) through t^25 ((-1)^k / (2k+1), k = 12 .. 1), |t| <= 3/16: first omitted
// term below 1e-21 of the value.
constexpr double kArctanTail[12] = {1.0 / 25, -1.0 / 23, 1.0 / 21, -1.0 / 19, 1.0 / 17, -1.0 / 15,
                                    1.0 / 13, -1.0 / 11, 1.0 / 9,  -1.0 / 7,  1.0 / 5,  -1.0 / 3};

// pi/2 in three parts: the first two with 33 significant bits, so that k times each is exact for
// |k| < 2^20, and the rest rounded (pi/2 - the three parts is 1e-37).
constexpr double kHalfPi1 = 0x1.921fb54400000p+0, kHalfPi2 = 0x1.0b4611a600000p-34,
                 kHalfPi3 = 0x1.3198a2e037073p-69;
constexpr double kTwoOverPi = 0x1.45f306dc9c883p-1;
// pi/2 and the arctangents of 1/4, 1/2, 1 as (high, low) pairs.
constexpr double kHalfPiHigh = 0x1.921fb54442d18p+0, kHalfPiLow = 0x1.1a62633145c07p-54;
constexpr double kArctanCentreHigh[4] = {0.0, 0x1.f5b75f92c80ddp-3, 0x1.dac670561bb4fp-2, 0x1.921fb54442d18p-1};
constexpr double kArctanCentreLow[4] = {0.0, 0x1.8ab6e3cf7afbdp-57, 0x1.a2b7f222f65e2p-56, 0x1.1a62633145c07p-55};

// Whether cos_sin reduces x: |x| <= 2^19 pi/2, the JAX path's bound (NaN and infinities not).
FRBJAX_INLINE bool reduces(double x) { return std::fabs(x) <= 524288.0 * 1.5707963267948966; }

// (cos, sin)(r + tail) for |r| <= pi/4 (a little beyond too), `tail` a correction of an ulp of r:
// 1 - r^2/2 with the roundings of r^2 and of the difference added back, the tail at first order.
FRBJAX_INLINE void cos_sin_near_zero(double r, double tail, double& cosine, double& sine) {
  double square, square_error;
  two_product(r, r, square, square_error);
  double sine_rest = r * square * horner(kSinTail, square);
  const double half = square / 2;
  const double lead = 1 - half;
  double cosine_rest = (((1 - lead) - half) - square_error / 2) + square * square * horner(kCosTail, square);
  // sin(r + d) = sin r + d cos r and cos(r + d) = cos r - d sin r to first order in d ~ ulp(r).
  sine_rest = sine_rest + tail * (lead + cosine_rest);
  cosine_rest = cosine_rest - tail * r;
  cosine = lead + cosine_rest;
  sine = r + sine_rest;
}

// (cos x, sin x) for |x| <= 2^19 pi/2 (DLMF 4.14).
FRBJAX_INLINE void cos_sin(double x, double& cosine, double& sine) {
  const double turns = std::nearbyint(x * kTwoOverPi);
  // x - k P1 and k P2 are exact; their difference is carried with its error.
  double head, error;
  two_sum(x - turns * kHalfPi1, -(turns * kHalfPi2), head, error);
  const double third = turns * kHalfPi3;
  const double r = head - third;
  const double tail = ((head - r) - third) + error;
  double c, s;
  cos_sin_near_zero(r, tail, c, s);
  // Quadrant k mod 4: (cos, sin)(k pi/2 + r) = (c, s), (-s, c), (-c, -s), (s, -c).
  const double quadrant = turns - 4 * std::floor(turns / 4);
  const bool swap = quadrant == 1 || quadrant == 3;
  const double cos_value = swap ? s : c, sin_value = swap ? c : s;
  cosine = (quadrant == 1 || quadrant == 2) ? -cos_value : cos_value;
  // sin(+-0) = +-0 (the polynomial's sum gives +0 for both).
  sine = x == 0 ? x : (quadrant >= 2 ? -sin_value : sin_value);
}

// (cos r, sin r) for |r| <= pi/4, no reduction (float32 through float64).
template <class R>
FRBJAX_INLINE void cos_sin_small(R r, R& cosine, R& sine) {
  double c, s;
  cos_sin_near_zero(double(r), 0.0, c, s);
  cosine = R(c);
  sine = R(s);
}

FRBJAX_INLINE void cos_sin(float x, float& cosine, float& sine) {
  double c, s;
  cos_sin(double(x), c, s);
  cosine = float(c);
  sine = float(s);
}

// The angle of the point (x, y) in [-pi, pi] (DLMF 4.23.34), finite arguments; atan2(+-0, -0) =
// +-pi as IEEE 754.
FRBJAX_INLINE double arctangent2(double y, double x) {
  double near = std::fabs(y), far = std::fabs(x);
  const bool swap = near > far;
  double smaller = swap ? far : near, larger = swap ? near : far;
  // Powers of two that keep Dekker's products from overflowing or underflowing (exact scalings).
  const double scale = larger > 0x1p500 ? 0x1p-600 : (larger < 0x1p-500 ? 0x1p600 : 1.0);
  smaller *= scale;
  larger = larger > 0 ? larger * scale : 1.0;  // (0, 0): t = 0
  // c by interval of a = smaller/larger: [0, 3/16), [3/16, 7/16), [7/16, 11/16), [11/16, 1], so that
  // |t| <= 3/16 and smaller - c larger is exact.
  const bool above_3 = 16 * smaller >= 3 * larger, above_7 = 16 * smaller >= 7 * larger,
             above_11 = 16 * smaller >= 11 * larger;
  // Selects, not an index into a table: a loop over points stays vectorisable.
  const double centre = above_11 ? 1.0 : (above_7 ? 0.5 : (above_3 ? 0.25 : 0.0));
  const double numerator = smaller - centre * larger;
  // t = numerator/(larger + c smaller), the roundings of the denominator and quotient carried in t_low.
  double denominator, denominator_low, product, product_low;
  two_sum(larger, centre * smaller, denominator, denominator_low);
  const double t = numerator / denominator;
  two_product(t, denominator, product, product_low);
  const double t_low = (((numerator - product) - product_low) - t * denominator_low) / denominator;
  const double reduced_rest = t_low + t * (t * t) * horner(kArctanTail, t * t);
  // The octant's angle: arctan c + r (no swap, x >= 0); pi/2 - arctan c - r (swap, x >= 0);
  // pi - arctan c - r (no swap, x < 0); pi/2 + arctan c + r (swap, x < 0).
  const bool negative_x = std::copysign(1.0, x) < 0;  // signbit, vectorisable
  const double sign = swap == negative_x ? 1.0 : -1.0;
  const double base = swap ? 1.0 : (negative_x ? 2.0 : 0.0);  // in units of pi/2 (exact multiples)
  const double centre_high = above_11  ? kArctanCentreHigh[3]
                             : above_7 ? kArctanCentreHigh[2]
                             : above_3 ? kArctanCentreHigh[1]
                                       : kArctanCentreHigh[0];
  const double centre_low = above_11  ? kArctanCentreLow[3]
                            : above_7 ? kArctanCentreLow[2]
                            : above_3 ? kArctanCentreLow[1]
                                      : kArctanCentreLow[0];
  double head, head_error, total, total_error;
  two_sum(base * kHalfPiHigh, sign * centre_high, head, head_error);
  two_sum(head, sign * t, total, total_error);
  const double angle =
      total + ((total_error + (head_error + (base * kHalfPiLow + sign * centre_low))) + sign * reduced_rest);
  return std::copysign(angle, y);
}

FRBJAX_INLINE float arctangent2(float y, float x) { return float(arctangent2(double(y), double(x))); }

// The functions above at count points, each as one vectorised loop, then the C library's where they
// do not apply: cos and sin where cos_sin does not reduce (|x| beyond 2^19 pi/2, or not finite),
// atan2 where an argument is not finite.  Out of line: code compiled with its products and sums fused
// (motion.hpp's section) calls them without taking them in, so that they keep the exact roundings
// their error-free transformations rely on.
template <class R>
FRBJAX_NOINLINE void cos_sin_points(const R* x, int count, R* cosine, R* sine) {
#pragma omp simd
  for (int i = 0; i < count; ++i) cos_sin(x[i], cosine[i], sine[i]);
  for (int i = 0; i < count; ++i) {
    if (!reduces(x[i])) {
      cosine[i] = std::cos(x[i]);
      sine[i] = std::sin(x[i]);
    }
  }
}

template <class R>
FRBJAX_NOINLINE void arctangent2_points(const R* y, const R* x, int count, R* angle) {
#pragma omp simd
  for (int i = 0; i < count; ++i) angle[i] = arctangent2(y[i], x[i]);
  for (int i = 0; i < count; ++i)
    if (!std::isfinite(y[i]) || !std::isfinite(x[i])) angle[i] = std::atan2(y[i], x[i]);
}

}  // namespace circular
}  // namespace frbjax
