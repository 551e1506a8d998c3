// Forward-mode dual numbers for the kernels' partial derivatives.
//
// Dual<T, N> carries a value and N directional derivatives.  The special functions are written once,
// templated on their number type: with T = double (or float) they give values; with Dual<double, N>
// the N partial derivatives in their arguments; with Dual<Dual<double, N>, N> the second ones.  A
// duplication step is an exact identity, so the derivative of the algorithm converges to the
// derivative of the function (DLMF 19.26.18-19.26.20).
//
// The one convention of the derivatives (as the JAX path's): sqrt's derivative at exactly 0 is 0, so
// that an argument that is exactly zero gives a finite (meaningless) partial derivative instead of
// inf * 0 = NaN in the other ones; the JAX rules ignore the tangent of such an argument.
#pragma once

#include <cmath>
#include <type_traits>

namespace frbjax {

template <class T, int N>
struct Dual {
  T v;
  T d[N];
  Dual() : v(0) {
    for (int i = 0; i < N; ++i) d[i] = T(0);
  }
  Dual(double value) : v(value) {  // NOLINT: constants promote implicitly
    for (int i = 0; i < N; ++i) d[i] = T(0);
  }
};

template <class T>
struct is_dual : std::false_type {};
template <class T, int N>
struct is_dual<Dual<T, N>> : std::true_type {};

// The plain value at the bottom of a (nested) dual number: branches compare these.
inline double value(double x) { return x; }
inline float value(float x) { return x; }
template <class T, int N>
inline auto value(const Dual<T, N>& x) {
  return value(x.v);
}

// The real type at the bottom (float or double).
template <class T>
struct real_of {
  using type = T;
};
template <class T, int N>
struct real_of<Dual<T, N>> {
  using type = typename real_of<T>::type;
};
template <class T>
using real_t = typename real_of<T>::type;

template <class T, int N>
inline Dual<T, N> operator+(const Dual<T, N>& a, const Dual<T, N>& b) {
  Dual<T, N> r;
  r.v = a.v + b.v;
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] + b.d[i];
  return r;
}
template <class T, int N>
inline Dual<T, N> operator-(const Dual<T, N>& a, const Dual<T, N>& b) {
  Dual<T, N> r;
  r.v = a.v - b.v;
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] - b.d[i];
  return r;
}
template <class T, int N>
inline Dual<T, N> operator-(const Dual<T, N>& a) {
  Dual<T, N> r;
  r.v = -a.v;
  for (int i = 0; i < N; ++i) r.d[i] = -a.d[i];
  return r;
}
template <class T, int N>
inline Dual<T, N> operator*(const Dual<T, N>& a, const Dual<T, N>& b) {
  Dual<T, N> r;
  r.v = a.v * b.v;
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] * b.v + a.v * b.d[i];
  return r;
}
template <class T, int N>
inline Dual<T, N> operator/(const Dual<T, N>& a, const Dual<T, N>& b) {
  Dual<T, N> r;
  T inverse = T(1) / b.v;
  r.v = a.v * inverse;
  for (int i = 0; i < N; ++i) r.d[i] = (a.d[i] - r.v * b.d[i]) * inverse;
  return r;
}
// Mixed with plain numbers (double constants of the algorithms).
template <class T, int N>
inline Dual<T, N> operator+(const Dual<T, N>& a, double b) {
  Dual<T, N> r = a;
  r.v = a.v + b;
  return r;
}
template <class T, int N>
inline Dual<T, N> operator+(double a, const Dual<T, N>& b) {
  return b + a;
}
template <class T, int N>
inline Dual<T, N> operator-(const Dual<T, N>& a, double b) {
  Dual<T, N> r = a;
  r.v = a.v - b;
  return r;
}
template <class T, int N>
inline Dual<T, N> operator-(double a, const Dual<T, N>& b) {
  return -b + a;
}
template <class T, int N>
inline Dual<T, N> operator*(const Dual<T, N>& a, double b) {
  Dual<T, N> r;
  r.v = a.v * b;
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] * b;
  return r;
}
template <class T, int N>
inline Dual<T, N> operator*(double a, const Dual<T, N>& b) {
  return b * a;
}
template <class T, int N>
inline Dual<T, N> operator/(const Dual<T, N>& a, double b) {
  return a * (1.0 / b);
}
template <class T, int N>
inline Dual<T, N> operator/(double a, const Dual<T, N>& b) {
  return Dual<T, N>(a) / b;
}
template <class T, int N, class U>
inline Dual<T, N>& operator+=(Dual<T, N>& a, const U& b) {
  a = a + b;
  return a;
}

template <class T, int N, class U>
inline Dual<T, N>& operator*=(Dual<T, N>& a, const U& b) {
  a = a * b;
  return a;
}

// f(a) with f(a.v) = value and f'(a.v) = slope, by the chain rule.
template <class T, int N, class U, class V>
inline Dual<T, N> chain(const Dual<T, N>& a, const U& value, const V& slope) {
  Dual<T, N> r;
  r.v = T(value);
  const T factor(slope);
  for (int i = 0; i < N; ++i) r.d[i] = a.d[i] * factor;
  return r;
}

// sqrt, with the derivative 0 at exactly 0 (the convention above).
template <class T, int N>
inline Dual<T, N> sqrt(const Dual<T, N>& a) {
  using std::sqrt;
  T root = sqrt(a.v);
  T slope = value(a.v) > 0 ? T(0.5) / root : T(0);
  return chain(a, root, slope);
}
template <class T, int N>
inline Dual<T, N> log(const Dual<T, N>& a) {
  using std::log;
  return chain(a, log(a.v), T(1) / a.v);
}
template <class T, int N>
inline Dual<T, N> log1p(const Dual<T, N>& a) {
  using std::log1p;
  return chain(a, log1p(a.v), T(1) / (a.v + 1.0));
}
template <class T, int N>
inline Dual<T, N> atan(const Dual<T, N>& a) {
  using std::atan;
  return chain(a, atan(a.v), T(1) / (a.v * a.v + 1.0));
}
template <class T, int N>
inline Dual<T, N> fabs(const Dual<T, N>& a) {
  return value(a) < 0 ? -a : a;
}

template <class T, int N>
inline Dual<T, N> exp(const Dual<T, N>& a) {
  using std::exp;
  T e = exp(a.v);
  return chain(a, e, e);
}
template <class T, int N>
inline Dual<T, N> expm1(const Dual<T, N>& a) {
  using std::exp;
  using std::expm1;
  return chain(a, expm1(a.v), exp(a.v));
}
template <class T, int N>
inline Dual<T, N> sin(const Dual<T, N>& a) {
  using std::cos;
  using std::sin;
  return chain(a, sin(a.v), cos(a.v));
}
template <class T, int N>
inline Dual<T, N> cos(const Dual<T, N>& a) {
  using std::cos;
  using std::sin;
  return chain(a, cos(a.v), -sin(a.v));
}
template <class T, int N>
inline Dual<T, N> tanh(const Dual<T, N>& a) {
  using std::tanh;
  T t = tanh(a.v);
  return chain(a, t, 1.0 - t * t);
}
template <class T, int N>
inline Dual<T, N> asinh(const Dual<T, N>& a) {
  using std::asinh;
  using std::sqrt;
  return chain(a, asinh(a.v), T(1.0) / sqrt(a.v * a.v + 1.0));
}
// atan2(y, x): d = (x dy - y dx) / (x^2 + y^2) (0 at the origin, where it has no derivative).
template <class T, int N>
inline Dual<T, N> atan2(const Dual<T, N>& y, const Dual<T, N>& x) {
  using std::atan2;
  Dual<T, N> r;
  r.v = atan2(y.v, x.v);
  T norm = x.v * x.v + y.v * y.v;
  if (!(value(norm) > 0)) return r;
  T x_scaled = x.v / norm, y_scaled = y.v / norm;
  for (int i = 0; i < N; ++i) r.d[i] = x_scaled * y.d[i] - y_scaled * x.d[i];
  return r;
}

template <class T, int N>
inline Dual<T, N> sinh(const Dual<T, N>& a) {
  using std::cosh;
  using std::sinh;
  return chain(a, sinh(a.v), cosh(a.v));
}
template <class T, int N>
inline Dual<T, N> cosh(const Dual<T, N>& a) {
  using std::cosh;
  using std::sinh;
  return chain(a, cosh(a.v), sinh(a.v));
}

}  // namespace frbjax
