// The theta series of a body's motion: the compiled form of
// frbjax/_regimes.py's `constants`, `reference` and `evaluate` with frbjax/_series.py's `coefficients`
// and `evaluate_series` (docs/theory.md §5, §9; the module note of _series.py derives every form).
//
// `series_record` computes a body's record once (the orbit's constants, the phase u0, the complete
// third-kind integral, the series' coefficients and q̂(0)); `series_motion_block` evaluates the
// working-frame unit L and q̂(tau) from it at up to kBlock times at once.  Uniformly rotating bodies
// get a stand-in record (their motion is formed in JAX around the kernels).
//
// The record and the evaluation at one point are written on any number type (`series_motion_point`):
// on dual numbers they give a body's evaluations' partial derivatives from one record of dual
// numbers per body (flow_jacobian.hpp's `SeriesFlow`), instead of the one-time motion's per point.
// Branches compare values (dual.hpp's `value`); the real type decides the number of terms.
#pragma once

#include <cmath>
#include <limits>

#include "carlson.hpp"
#include "circular.hpp"
#include "dual.hpp"
#include "motion.hpp"

namespace frbjax {

// cos and sin, and atan2: circular.hpp's vectorisable forms for real numbers, dual.hpp's on dual ones.
template <class T>
FRBJAX_INLINE void series_cos_sin(const T& x, T& cosine, T& sine) {
  if constexpr (is_dual<T>::value) {
    cosine = cos(x);
    sine = sin(x);
  } else {
    circular::cos_sin(x, cosine, sine);
  }
}
template <class T>
FRBJAX_INLINE T series_arctangent2(const T& y, const T& x) {
  if constexpr (is_dual<T>::value)
    return atan2(y, x);
  else
    return circular::arctangent2(y, x);
}

template <class R>
struct SeriesLayout {
  static constexpr int terms = sizeof(R) == 8 ? 8 : 5;
  static constexpr double largest_nome = sizeof(R) == 8 ? 0.45 : 0.35;
  enum : int {
    kAmplitude = 0,  // 3: L's amplitudes
    kRate = 3,
    kMc = 4,
    kAlpha = 5,
    kPrecession = 6,
    kU0 = 7,
    kThirdComplete = 8,  // Pi(nu|m) (- K): one half period of the expanded integral
    kSeriesAmplitude = 9,
    kOrigin = 10,
    kQuarter = 11,
    kSlope = 12,
    kComplementary = 13,
    kPeriodic = 14,
    kComplementaryRows = 15,  // 4 x 2
    kComplementaryLogNome = 23,
    kComplementaryScale = 24,
    kComplementaryCnFactor = 25,
    kMinor = 26,
    kReference = 27,      // 4: q̂(0), psi counted from tau = 0
    kPsiReference = 31,   // the series' psi at tau = 0
    kRows = 32,           // 4 x terms
  };
  static constexpr int size = kRows + 4 * terms;
};

// (q, q/m) of parameter m <= 1/2 (DLMF 19.5.5 through lambda^21, no cancellation as m -> 0).
template <class R>
void landen_nome(R m, R mc, R& q, R& q_over_m) {
  using std::sqrt;
  R root = sqrt(mc), fourth = sqrt(root);
  R lam_over_m = 1 / (2 * (1 + root) * (1 + fourth) * (1 + fourth));
  R lam = m * lam_over_m, lam4 = lam * lam * lam * lam;
  R series = 1 + lam4 * (2 + lam4 * (15 + lam4 * (150 + lam4 * (1707 + lam4 * 20910))));
  q = lam * series;
  q_over_m = lam_over_m * series;
}

// (q, q/m) for 0 <= m < 1: the Landen series for m <= 1/2, else ln q ln q' = pi^2 (DLMF 22.2.1).
template <class R>
void nome(R m, R mc, R& q, R& q_over_m) {
  using std::exp;
  using std::log;
  if (value(m) <= 0.5) return landen_nome(m, mc, q, q_over_m);
  R q_complement, unused;
  landen_nome(mc, m, q_complement, unused);
  q = exp(R(9.869604401089358) / log(q_complement));
  q_over_m = q / m;
}

// The series' coefficients (`_series.coefficients`) for characteristic chi = nu <= 0; `quarter` is
// K(m) = R_F(0, mc, 1), which the caller has computed already.
template <class R>
void series_coefficients(R m, R mc, R nu, R complete, R quarter, R* record) {
  using L = SeriesLayout<real_t<R>>;
  using std::exp;
  using std::expm1;
  using std::sin;
  using std::sqrt;
  const R pi = R(3.141592653589793);
  const bool moving = value(nu) < 0;
  const R minus_chi = moving ? -nu : R(1);
  const R gap = m + minus_chi;
  const R complement_parameter = value(m) > 0.5 ? m : R(0.5);
  const R shift_integral = elliprf<R>(m / gap, m * (1 + minus_chi) / gap, R(1));
  const R distance_integral = elliprf<R>(minus_chi / (1 + minus_chi), gap / (1 + minus_chi), R(1));
  const R complement_quarter = elliprf<R>(R(0), complement_parameter, R(1));
  R q, q_over_m;
  nome(m, mc, q, q_over_m);
  const R shift = sqrt(minus_chi / gap) * shift_integral;
  const R distance = distance_integral / sqrt(1 + minus_chi);
  const R rho = exp(-pi * distance / quarter);
  const R amplitude = moving ? sqrt(minus_chi) / sqrt((1 + minus_chi) * gap) : R(0);
  const R odd_scale = 2 * sqrt(sqrt(q_over_m));
  const R mc_fourth = sqrt(sqrt(mc));
  const R two_beta = pi * distance / quarter;
  R origin = -expm1(-two_beta);
  const R shift_decay = exp(-pi * shift / quarter);
  const R shift_gap = -expm1(-2 * pi * shift / quarter);
  const R beta_decay = exp(-two_beta);
  const R beta_gap = -expm1(-2 * two_beta);
  const R q_squared = q * q, shift_decay_squared = shift_decay * shift_decay;
  const R beta_decay_squared = beta_decay * beta_decay;
  R q_odd = 1, q_power = 1, q_even_power = 1, rho_power = 1, shift_power = 1;
  R shift_square_power = 1, shift_complement = 0, beta_power = beta_decay, beta_complement = origin;
  const int terms = L::terms;
  R* rows = record + L::kRows;
  for (int j = 0; j < terms; ++j) {
    const int n = j + 1;
    q_power *= q;
    rho_power *= rho;
    shift_power *= shift_decay;
    rows[j] = odd_scale * (j % 2 ? -1 : 1) * q_odd;
    rows[terms + j] = odd_scale * mc_fourth * q_odd;
    const R growing = q_odd * rho_power;
    const R decaying = q_odd * q_power * shift_power;
    shift_complement = shift_complement + shift_square_power * shift_gap;
    shift_square_power *= shift_decay_squared;
    const R sign = n % 2 ? R(-1) : R(1);
    rows[2 * terms + j] = sign * (growing + decaying);
    rows[3 * terms + j] = moving ? sign * growing * shift_complement : R(0);
    if (n < terms) {
      beta_complement = beta_complement + beta_power * beta_gap;
      beta_power *= beta_decay_squared;
      origin = origin + sign * decaying * beta_complement;
    }
    q_even_power *= q_squared;
    q_odd *= q_even_power;
  }
  const bool without_first_kind = value(nu) >= -1;
  // The complementary series from the nome q' of mc (stand-ins where m <= 1/2).
  const bool candidate = value(m) > 0.5;
  R q_c, q_c_over_mc;
  nome(candidate ? mc : R(0.5), candidate ? m : R(0.5), q_c, q_c_over_mc);
  const R sin_shift = sin(pi / 2 * shift / complement_quarter);
  const R cos_shift = sin(pi / 2 * distance / complement_quarter);
  const R cos_triple = cos_shift * (4 * cos_shift * cos_shift - 3);
  const R sin_triple = sin_shift * (3 - 4 * sin_shift * sin_shift);
  const R sin_double = 2 * sin_shift * cos_shift;
  const R cos_double = (cos_shift - sin_shift) * (cos_shift + sin_shift);
  const R q_c4 = q_c * q_c * q_c * q_c;
  const R theta_derivative = 4 * sin_double * (q_c - 4 * q_c4 * cos_double);
  const R theta = 1 - 2 * q_c * cos_double + 2 * q_c4 * (2 * cos_double * cos_double - 1);
  const R zeta = (pi / 2) / complement_quarter * theta_derivative / theta;
  const R slope_complementary = moving ? (without_first_kind ? -minus_chi : m) / gap + amplitude * zeta : R(0);
  R* complementary_rows = record + L::kComplementaryRows;
  const R rows_c[8] = {cos_shift, q_c * cos_triple, sin_shift, q_c * sin_triple, R(1), -q_c, q_c, q_c * q_c};
  for (int k = 0; k < 8; ++k) complementary_rows[k] = rows_c[k];
  const bool complementary = value(q) > L::largest_nome;
  record[L::kSeriesAmplitude] = amplitude;
  record[L::kOrigin] = origin;
  record[L::kQuarter] = quarter;
  record[L::kSlope] = complementary ? slope_complementary : complete / quarter;
  record[L::kComplementary] = R(complementary ? 1 : 0);
  record[L::kPeriodic] = R(1);
  record[L::kComplementaryLogNome] = -pi * quarter / complement_quarter;
  record[L::kComplementaryScale] = pi / complement_quarter;
  record[L::kComplementaryCnFactor] = 1 / sqrt(sqrt(q_c_over_mc));
}

// (sn_r, cn_r) up to a common positive factor and the third kind's angle's parts at u_r (|u_r| <= K)
// from the complementary series (`_series._evaluate_complementary`).
template <class R>
void complementary_parts(const R* record, R reduced, R& sn_scaled, R& cn_scaled, R& real, R& imaginary) {
  using L = SeriesLayout<real_t<R>>;
  using Real = real_t<R>;
  using std::exp;
  using std::expm1;
  using std::fabs;
  const R* rows = record + L::kComplementaryRows;
  const R sign = value(reduced) < 0 ? R(-1) : R(1);
  const R distance = fabs(reduced) * record[L::kComplementaryScale];
  const R sum = record[L::kComplementaryLogNome] + distance;
  const R gap = value(sum) < 0 ? sum : R(0);  // min(sum, 0)
  const R half = exp(-distance / Real(2)), d = -expm1(-distance), f = exp(gap), g = -expm1(gap);
  const R e = half * half, e2 = e * e, triple = Real(1) + e + e2;
  sn_scaled = sign * d * (rows[4] + rows[5] * f * triple);
  cn_scaled = record[L::kComplementaryCnFactor] * half * (g - rows[6] * e + rows[7] * (f * f) * (Real(1) + e2 * e2));
  real = rows[0] * (Real(1) + e) + rows[1] * f * (Real(1) + e * e2);
  imaginary = sign * d * (rows[2] + rows[3] * f * triple);
}

// The same from the direct series (`_series.evaluate_series`): straight-line code, vectorised over a
// block's points.
template <class R, bool Jacobi>
FRBJAX_INLINE void direct_parts(const R* record, R reduced, R& sn_scaled, R& cn_scaled, R& real, R& imaginary) {
  using L = SeriesLayout<real_t<R>>;
  constexpr int terms = L::terms;
  const R* rows = record + L::kRows;
  const R v = reduced * R(1.5707963267948966) / record[L::kQuarter];
  R sines[2 * terms], cosines[2 * terms];
  if constexpr (is_dual<R>::value) {
    // On dual numbers of reals: the multiples' values by the same recurrence, their derivatives
    // d sin(k v) = k cos(k v) dv and d cos(k v) = -k sin(k v) dv at once.
    using V = decltype(v.v);
    V sine[2 * terms], cosine[2 * terms];
    circular::cos_sin(v.v, cosine[0], sine[0]);
    for (int k = 1; k < 2 * terms; ++k) {
      cosine[k] = cosine[k - 1] * cosine[0] - sine[k - 1] * sine[0];
      sine[k] = sine[k - 1] * cosine[0] + cosine[k - 1] * sine[0];
    }
    for (int k = 0; k < 2 * terms; ++k) {
      sines[k] = chain(v, sine[k], V(k + 1) * cosine[k]);
      cosines[k] = chain(v, cosine[k], -V(k + 1) * sine[k]);
    }
  } else {
    R sin_v, cos_v;
    series_cos_sin(v, cos_v, sin_v);
    sines[0] = sin_v;
    cosines[0] = cos_v;
    for (int k = 1; k < 2 * terms; ++k) {
      cosines[k] = cosines[k - 1] * cos_v - sines[k - 1] * sin_v;
      sines[k] = sines[k - 1] * cos_v + cosines[k - 1] * sin_v;
    }
  }
  sn_scaled = R(0);
  cn_scaled = R(0);
  if (Jacobi) {
    for (int j = 0; j < terms; ++j) {
      sn_scaled = sn_scaled + rows[j] * sines[2 * j];
      cn_scaled = cn_scaled + rows[terms + j] * cosines[2 * j];
    }
  }
  real = record[L::kOrigin];
  imaginary = R(0);
  for (int j = 0; j < terms; ++j) {
    real = real - real_t<R>(2) * rows[2 * terms + j] * (sines[j] * sines[j]);
    imaginary = imaginary - rows[3 * terms + j] * sines[2 * j + 1];
  }
}

// The third kind's angle's parts at one u_r (the record's phase): either series.
template <class R>
void angle_parts(const R* record, R reduced, R& real, R& imaginary) {
  R sn_scaled, cn_scaled;
  if (value(record[SeriesLayout<real_t<R>>::kComplementary]) != 0)
    complementary_parts<R>(record, reduced, sn_scaled, cn_scaled, real, imaginary);
  else
    direct_parts<R, false>(record, reduced, sn_scaled, cn_scaled, real, imaginary);
}

// The expanded integral from 0 to u_r: u_r slope + A arg theta(...).
template <class R>
FRBJAX_INLINE R reduced_third_kind(const R* record, R reduced, R real, R imaginary) {
  using L = SeriesLayout<real_t<R>>;
  return reduced * record[L::kSlope] + record[L::kSeriesAmplitude] * series_arctangent2(imaginary, real);
}

// psi's bounded part at unit L (l1, l2, l3) and the integral's value: orientation (atan2(l2, l_o) -
// alpha third_kind), `_regimes.evaluate` and `reference`.
template <class R>
FRBJAX_INLINE R bounded_angle(const R* record, R l1, R l2, R l3, R third_kind) {
  using L = SeriesLayout<real_t<R>>;
  const bool minor = value(record[L::kMinor]) != 0;
  const R angle = series_arctangent2(l2, minor ? l1 : l3) - record[L::kAlpha] * third_kind;
  return minor ? -angle : angle;
}

// A body's record from its sorted moments and unit working-frame L (in[0..5]) and its regime.
template <class R>
void series_record(const R* given, int regime, R* record) {
  using L = SeriesLayout<real_t<R>>;
  using std::sqrt;
  for (int k = 0; k < L::size; ++k) record[k] = R(0);
  R in[6];
  const R safe[6] = {R(1), R(2), R(3), R(0.3), R(0), R(0.9539392014169456)};  // `_regimes._SAFE_MAJOR`
  const bool uniform = regime == kUniform || regime < 0 || regime > kUniform;
  for (int k = 0; k < 6; ++k) in[k] = uniform ? safe[k] : given[k];
  if (uniform) regime = kMajor;
  const bool minor = regime == kMinor;
  record[L::kMinor] = R(minor ? 1 : 0);
  if (regime == kSeparatrix) {
    const SeparatrixOrbit<R> orbit = separatrix_orbit(in);
    record[L::kAmplitude] = orbit.amplitude_1;
    record[L::kAmplitude + 1] = 1;
    record[L::kAmplitude + 2] = orbit.amplitude_3;
    record[L::kRate] = orbit.rate;
    record[L::kMc] = 0;
    record[L::kAlpha] = orbit.delta;
    record[L::kPrecession] = 1 / in[1];
    record[L::kU0] = orbit.u0;
    record[L::kThirdComplete] = complete_third_kind<R>(R(-0.5), R(0.5), R(0.5));  // stand-in: no periods
    // The limit m = 1 of the complementary series (`_series.at_separatrix`): third kind
    // A arctan(tan beta' tanh u), sin beta' = A1, cos beta' = A3, A = (1 + A1)/A3, no slope.
    series_coefficients<R>(R(0.5), R(0.5), R(-0.5), record[L::kThirdComplete], elliprf<R>(R(0), R(0.5), R(1)), record);
    const R rows_c[8] = {orbit.amplitude_3, 0, orbit.amplitude_1, 0, 1, 0, 0, 0};
    for (int k = 0; k < 8; ++k) record[L::kComplementaryRows + k] = rows_c[k];
    record[L::kQuarter] = 1;
    record[L::kSeriesAmplitude] = (1 + orbit.amplitude_1) / orbit.amplitude_3;
    record[L::kSlope] = 0;
    record[L::kComplementary] = 1;
    record[L::kPeriodic] = 0;
    record[L::kComplementaryLogNome] = R(-std::numeric_limits<real_t<R>>::infinity());
    record[L::kComplementaryScale] = 2;
    record[L::kComplementaryCnFactor] = 2;
  } else {
    const EllipticOrbit<R> orbit = elliptic_orbit(in, minor);
    for (int k = 0; k < 3; ++k) record[L::kAmplitude + k] = orbit.amplitude[k];
    record[L::kRate] = orbit.rate;
    record[L::kMc] = orbit.mc;
    record[L::kAlpha] = orbit.alpha;
    record[L::kPrecession] = orbit.precession;
    const R m = orbit.m, mc = orbit.mc, sn0 = orbit.sn0, cn0 = orbit.cn0;
    // The phase u0 = F(am0|m) = sn0 R_F(cn0^2, dn0^2, 1), or from the quarter period where cn0^2 <
    // mc sn0^2 (`_regimes.constants`).
    const R mc_sn0_squared = mc * (sn0 * sn0);
    const bool reflected = value(cn0 * cn0) < value(mc_sn0_squared);
    const R dn0_squared = cn0 * cn0 + mc_sn0_squared;
    const R phase_integral = reflected ? elliprf<R>(mc_sn0_squared, mc, dn0_squared)
                                       : elliprf<R>(cn0 * cn0, dn0_squared, R(1));
    const R quarter = elliprf<R>(R(0), mc, R(1));
    const R sign = value(sn0) < 0 ? R(-1) : R(1);
    record[L::kU0] = reflected ? sign * (quarter - cn0 * phase_integral) : sn0 * phase_integral;
    const R complete = complete_third_kind<R>(orbit.nu, m, mc);
    record[L::kThirdComplete] = complete;
    series_coefficients<R>(m, mc, orbit.nu, complete, quarter, record);
  }
  // psi at u0 on the given unit L itself (`_regimes.reference`).  The charts count psi from tau = 0
  // (psi - psi(0)), as the one-time motion's do: q = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ q̂(tau) ⊗ conj(P) is the
  // same (the rotation by psi(0) about the spatial axis cancels), and both kernels then compute one
  // function, whose derivatives the one-time kernel gives.
  R real, imaginary;
  angle_parts<R>(record, record[L::kU0], real, imaginary);
  record[L::kPsiReference] =
      bounded_angle<R>(record, in[3], in[4], in[5], reduced_third_kind<R>(record, record[L::kU0], real, imaginary));
  chart<R>(R(1), R(0), in[3], in[4], in[5], minor, record + L::kReference);
}

// Unit L (3) and q̂(tau) (4) in the working frame at one time tau of one body from its record:
// `series_motion_block`'s operations for one point, on any number type (for dual numbers).
template <class T>
void series_motion_point(const T* record, const T& tau, T* out) {
  using L = SeriesLayout<real_t<T>>;
  using std::sqrt;
  const bool periodic = value(record[L::kPeriodic]) != 0;
  const T u = record[L::kU0] + record[L::kRate] * tau;
  const double turns = periodic ? std::nearbyint(double(value(u / (2.0 * record[L::kQuarter])))) : 0.0;
  const T reduced = u - 2.0 * record[L::kQuarter] * turns;
  T sn_scaled, cn_scaled, real, imaginary;
  if (value(record[L::kComplementary]) != 0)
    complementary_parts<T>(record, reduced, sn_scaled, cn_scaled, real, imaginary);
  else
    direct_parts<T, true>(record, reduced, sn_scaled, cn_scaled, real, imaginary);
  const bool minor = value(record[L::kMinor]) != 0;
  const T norm = sqrt(sn_scaled * sn_scaled + cn_scaled * cn_scaled);
  const double parity = turns - 2 * std::floor(turns / 2) != 0 ? -1.0 : 1.0;
  const T sn = parity * sn_scaled / norm, cn = parity * cn_scaled / norm;
  const T dn = sqrt(cn * cn + record[L::kMc] * (sn * sn));
  out[0] = record[L::kAmplitude] * (minor ? dn : cn);
  out[1] = record[L::kAmplitude + 1] * sn;
  out[2] = record[L::kAmplitude + 2] * (minor ? cn : dn);
  const T third_kind = 2.0 * turns * record[L::kThirdComplete] + reduced_third_kind<T>(record, reduced, real, imaginary);
  const T angle = bounded_angle<T>(record, out[0], out[1], out[2], third_kind);
  const T psi = record[L::kPrecession] * tau + (angle - record[L::kPsiReference]);
  T half_cos, half_sin;
  series_cos_sin(psi / 2.0, half_cos, half_sin);
  chart<T>(half_cos, half_sin, out[0], out[1], out[2], minor, out + 3);
}

// Each stage of `series_motion_block` is a loop over a block's points (motion.hpp's kBlock), which the
// compiler vectorises (circular.hpp's functions are straight-line code).
// Unit L (3) and, with `Attitude`, q̂(tau) (4) in the working frame at count <= kBlock times tau of
// one body, from its record (`_regimes.evaluate`): out[component][point].
template <class R, bool Attitude>
void series_motion_block(const R* record, const R* tau, int count, R (&out)[7][kBlock]) {
  using L = SeriesLayout<R>;
  R turns[kBlock], reduced[kBlock], sn_scaled[kBlock], cn_scaled[kBlock], real[kBlock], imaginary[kBlock];
  const R phase = record[L::kU0], rate = record[L::kRate], quarter = record[L::kQuarter];
  const bool periodic = record[L::kPeriodic] != 0;
#pragma omp simd
  for (int i = 0; i < count; ++i) {
    const R u = phase + rate * tau[i];
    turns[i] = periodic ? std::nearbyint(u / (2 * quarter)) : R(0);
    reduced[i] = u - 2 * quarter * turns[i];
  }
  if (record[L::kComplementary] != 0) {
    for (int i = 0; i < count; ++i)
      complementary_parts<R>(record, reduced[i], sn_scaled[i], cn_scaled[i], real[i], imaginary[i]);
  } else {
#pragma omp simd
    for (int i = 0; i < count; ++i)
      direct_parts<R, true>(record, reduced[i], sn_scaled[i], cn_scaled[i], real[i], imaginary[i]);
  }
  const bool minor = record[L::kMinor] != 0;
  const R mc = record[L::kMc], precession = record[L::kPrecession], complete = record[L::kThirdComplete];
  const R psi_reference = record[L::kPsiReference];
#pragma omp simd
  for (int i = 0; i < count; ++i) {
    const R norm = std::sqrt(sn_scaled[i] * sn_scaled[i] + cn_scaled[i] * cn_scaled[i]);
    // turns odd: sn and cn change sign (turns is an integer, so the difference is 0 or 1).
    const R parity = turns[i] - 2 * std::floor(turns[i] / 2) != 0 ? R(-1) : R(1);
    const R sn = parity * sn_scaled[i] / norm, cn = parity * cn_scaled[i] / norm;
    const R dn = std::sqrt(cn * cn + mc * (sn * sn));
    const R l1 = record[L::kAmplitude] * (minor ? dn : cn);
    const R l2 = record[L::kAmplitude + 1] * sn;
    const R l3 = record[L::kAmplitude + 2] * (minor ? cn : dn);
    out[0][i] = l1;
    out[1][i] = l2;
    out[2][i] = l3;
  }
  if (!Attitude) return;
  R half_angle[kBlock];
#pragma omp simd
  for (int i = 0; i < count; ++i) {
    const R third_kind = 2 * turns[i] * complete + reduced_third_kind<R>(record, reduced[i], real[i], imaginary[i]);
    const R angle = bounded_angle<R>(record, out[0][i], out[1][i], out[2][i], third_kind);
    const R psi = precession * tau[i] + (angle - psi_reference);
    half_angle[i] = psi / 2;
  }
  R half_cos[kBlock], half_sin[kBlock];
  circular::cos_sin_points(half_angle, count, half_cos, half_sin);
  // Vectorised without `omp simd`, which GCC 12 does not apply to a loop with a local array.
  for (int i = 0; i < count; ++i) {
    R q[4];
    chart<R>(half_cos[i], half_sin[i], out[0][i], out[1][i], out[2][i], minor, q);
    for (int k = 0; k < 4; ++k) out[3 + k][i] = q[k];
  }
}

// The same with out (count, 7 or 3), row-major.
template <class R, bool Attitude>
void series_motion_rows(const R* record, const R* tau, int count, R* out) {
  constexpr int outputs = Attitude ? 7 : 3;
  R block[7][kBlock];
  series_motion_block<R, Attitude>(record, tau, count, block);
  for (int i = 0; i < count; ++i)
    for (int k = 0; k < outputs; ++k) out[outputs * i + k] = block[k][i];
}

}  // namespace frbjax
