// frbjax._kernels: the compiled CPU kernels, exported to JAX as typed XLA FFI handlers.
//
// Every kernel here is elementwise: its inputs are K arrays of one shape (frbjax broadcasts them
// first), of float32 or float64, and its one result has that shape with a trailing axis of
//   order 0: the value;
//   order 1: the value and its K partial derivatives;
//   order 2: the value, its K partial derivatives and the K x K second ones (row-major).
// The derivatives come from the same templated scalar code run on dual numbers (dual.hpp), so that
// JAX's derivative rules (frbjax/special/_compiled.py) are linear in the tangents.
//
// The module's functions: `handlers()` returns {target name: PyCapsule of its XLA_FFI_Handler};
// `jaxlib_version()` the jaxlib whose FFI headers they were built with.
#include <Python.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>

#include "carlson.hpp"
#include "body.hpp"
#include "flow_jacobian.hpp"
#include "free_flow.hpp"
#include "jacobi.hpp"
#include "motion.hpp"
#include "parallel.hpp"
#include "series.hpp"
#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace frbjax {
namespace {

// Each function: its arity, name and value on any number type; the partial derivatives come from the
// value on dual numbers unless `partials` gives them in closed form (then their own derivatives come
// from it on dual numbers).
struct Rf {
  static constexpr int arity = 3;
  static constexpr bool closed_partials = false;
  static constexpr const char* name = "elliprf";
  template <class T>
  static T eval(const T* a) {
    return elliprf(a[0], a[1], a[2]);
  }
};
struct Rd {
  static constexpr bool closed_partials = false;
  static constexpr int arity = 3;
  static constexpr const char* name = "elliprd";
  template <class T>
  static T eval(const T* a) {
    return elliprd(a[0], a[1], a[2]);
  }
};
struct Rj {
  static constexpr bool closed_partials = false;
  static constexpr int arity = 4;
  static constexpr const char* name = "elliprj";
  template <class T>
  static T eval(const T* a) {
    return elliprj(a[0], a[1], a[2], a[3]);
  }
};
struct Rc {
  static constexpr int arity = 2;
  static constexpr bool closed_partials = true;
  static constexpr const char* name = "elliprc";
  template <class T>
  static T eval(const T* a) {
    return elliprc(a[0], a[1]);
  }
  // R_C(x, y) = R_F(x, y, y) and DLMF 19.18.1 (the closed forms' own derivatives cancel near x = y):
  // dR_C/dx = -R_D(y, y, x)/6, dR_C/dy = -R_D(x, y, y)/3 for y > 0; infinite at x = 0, where the
  // JAX rule ignores the tangent of x (a finite stand-in here).  The principal value (y < 0) through
  // its formula on dual numbers.
  template <class T>
  static void partials(const T* a, T* out) {
    const T& x = a[0];
    const T& y = a[1];
    if (value(y) > 0) {
      out[0] = value(x) > 0 ? -elliprd(y, y, x) / 6.0 : T(0.0);
      out[1] = -elliprd(x, y, y) / 3.0;
      return;
    }
    Dual<T, 2> dx(0.0), dy(0.0);
    dx.v = x;
    dx.d[0] = T(1.0);
    dy.v = y;
    dy.d[1] = T(1.0);
    Dual<T, 2> result = elliprc(dx, dy);
    out[0] = result.d[0];
    out[1] = result.d[1];
  }
};

constexpr int width(int arity, int order) {
  return order == 0 ? 1 : order == 1 ? 1 + arity : 1 + arity + arity * arity;
}

template <class F, int Order, class R>
void evaluate(std::size_t begin, std::size_t end, const R* const* inputs, R* output) {
  constexpr int K = F::arity;
  constexpr int W = width(K, Order);
  for (std::size_t i = begin; i < end; ++i) {
    R* out = output + i * W;
    if constexpr (Order == 0) {
      R arguments[K];
      for (int j = 0; j < K; ++j) arguments[j] = inputs[j][i];
      out[0] = F::template eval<R>(arguments);
    } else if constexpr (F::closed_partials && Order == 1) {
      R arguments[K];
      for (int j = 0; j < K; ++j) arguments[j] = inputs[j][i];
      out[0] = F::template eval<R>(arguments);
      F::template partials<R>(arguments, out + 1);
    } else if constexpr (F::closed_partials) {
      using D = Dual<R, K>;
      R plain[K];
      D arguments[K];
      for (int j = 0; j < K; ++j) {
        plain[j] = inputs[j][i];
        arguments[j] = D(0.0);
        arguments[j].v = inputs[j][i];
        arguments[j].d[j] = R(1);
      }
      out[0] = F::template eval<R>(plain);
      D first[K];
      F::template partials<D>(arguments, first);
      for (int j = 0; j < K; ++j) {
        out[1 + j] = first[j].v;
        for (int k = 0; k < K; ++k) out[1 + K + j * K + k] = first[j].d[k];
      }
    } else if constexpr (Order == 1) {
      using D = Dual<R, K>;
      D arguments[K];
      for (int j = 0; j < K; ++j) {
        arguments[j] = D(0.0);
        arguments[j].v = inputs[j][i];
        arguments[j].d[j] = R(1);
      }
      D result = F::template eval<D>(arguments);
      out[0] = result.v;
      for (int j = 0; j < K; ++j) out[1 + j] = result.d[j];
    } else {
      using D1 = Dual<R, K>;
      using D2 = Dual<D1, K>;
      D2 arguments[K];
      for (int j = 0; j < K; ++j) {
        arguments[j] = D2(0.0);
        arguments[j].v.v = inputs[j][i];
        arguments[j].v.d[j] = R(1);
        arguments[j].d[j].v = R(1);
      }
      D2 result = F::template eval<D2>(arguments);
      out[0] = result.v.v;
      for (int j = 0; j < K; ++j) out[1 + j] = result.v.d[j];
      for (int j = 0; j < K; ++j)
        for (int k = 0; k < K; ++k) out[1 + K + j * K + k] = result.d[j].d[k];
    }
  }
}

// The first `k` arguments' data, each checked to have the result's dtype and `count` elements (a
// kernel reads exactly that many from each).
template <class R>
ffi::Error gather(ffi::RemainingArgs& arguments, int k, std::size_t count, ffi::DataType dtype, const char* name,
                  const R** inputs) {
  for (int j = 0; j < k; ++j) {
    auto buffer = arguments.get<ffi::AnyBuffer>(j);
    if (!buffer.has_value()) return buffer.error();
    if (buffer->element_type() != dtype || buffer->element_count() != count)
      return ffi::Error::InvalidArgument(std::string(name) + ": the arguments must have the result's dtype and size");
    inputs[j] = static_cast<const R*>(buffer->untyped_data());
  }
  return ffi::Error::Success();
}

// `run(R())` with R the result's float type (float64 or float32), after checking the number of
// arguments; the errors name the kernel.
template <class Run>
ffi::Error by_float_type(const std::string& name, std::size_t arity, const ffi::RemainingArgs& arguments,
                         const ffi::AnyBuffer& result, Run run) {
  if (arguments.size() != arity) return ffi::Error::InvalidArgument(name + ": wrong number of arguments");
  switch (result.element_type()) {
    case ffi::DataType::F64:
      return run(double());
    case ffi::DataType::F32:
      return run(float());
    default:
      return ffi::Error::InvalidArgument(name + ": float32 or float64 only");
  }
}

// Points per chunk of the thread pool (parallel.hpp): a chunk of tens of microseconds at a kernel's
// cost per point (values ~50 ns, first derivatives a few times that, second ones tens of times).
constexpr std::size_t grain(int order) { return order == 0 ? 1024 : order == 1 ? 256 : 32; }

template <class F, int Order, class R>
ffi::Error run(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  constexpr int K = F::arity;
  const R* inputs[K];
  std::size_t count = result.element_count() / width(K, Order);
  ffi::Error checked = gather<R>(arguments, K, count, result.element_type(), F::name, inputs);
  if (checked.failure()) return checked;
  R* output = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(Order),
               [&](std::size_t begin, std::size_t end) { evaluate<F, Order, R>(begin, end, inputs, output); });
  return ffi::Error::Success();
}

template <class F, int Order>
ffi::Error elementwise(ffi::ThreadPool pool, ffi::RemainingArgs arguments, ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type(std::string(F::name), F::arity, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run<F, Order, R>(pool, arguments, *result);
  });
}

// Jacobi's functions: (u, m, mc) -> (sn, cn, dn, am) per point, values only (the JVP rule of
// frbjax/special/_compiled.py is written with them and R_D).
template <class R>
ffi::Error run_ellipj(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  const R* inputs[3];
  std::size_t count = result.element_count() / 4;
  ffi::Error checked = gather<R>(arguments, 3, count, result.element_type(), "ellipj", inputs);
  if (checked.failure()) return checked;
  R* out = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(0), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      JacobiValues<R> values = ellipj(inputs[0][i], inputs[1][i], inputs[2][i]);
      out[4 * i] = values.sn;
      out[4 * i + 1] = values.cn;
      out[4 * i + 2] = values.dn;
      out[4 * i + 3] = values.am;
    }
  });
  return ffi::Error::Success();
}

ffi::Error ellipj_values(ffi::ThreadPool pool, ffi::RemainingArgs arguments, ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type("ellipj", 3, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_ellipj<R>(pool, arguments, *result);
  });
}

XLA_FFI_DEFINE_HANDLER(Ellipj_0, ellipj_values, ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());

#define FRBJAX_HANDLER(F, ORDER)                                                                     \
  XLA_FFI_DEFINE_HANDLER(F##_##ORDER, (elementwise<F, ORDER>),                                     \
                         ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>())

FRBJAX_HANDLER(Rf, 0);
FRBJAX_HANDLER(Rf, 1);
FRBJAX_HANDLER(Rf, 2);
FRBJAX_HANDLER(Rd, 0);
FRBJAX_HANDLER(Rd, 1);
FRBJAX_HANDLER(Rd, 2);
FRBJAX_HANDLER(Rj, 0);
FRBJAX_HANDLER(Rj, 1);
FRBJAX_HANDLER(Rj, 2);
FRBJAX_HANDLER(Rc, 0);
FRBJAX_HANDLER(Rc, 1);
FRBJAX_HANDLER(Rc, 2);

// The working-frame motion at one time per point (motion.hpp): inputs J1, J2, J3, l1, l2, l3, tau (the
// result's dtype) and the regime (int32), all of one size; per point and output (3 with `Attitude`
// false, 11 with it) the value (order 0), and its 7 partial derivatives (order 1) and their 7 x 7
// second ones (order 2) after it.
template <int Order, bool Attitude, class R>
ffi::Error run_motion(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  constexpr int K = kMotionInputs;
  constexpr int outputs = Attitude ? kMotionOutputs : 3;
  constexpr int W = width(K, Order);
  const R* inputs[K];
  std::size_t count = result.element_count() / (outputs * W);
  ffi::Error checked = gather<R>(arguments, K, count, result.element_type(), "motion", inputs);
  if (checked.failure()) return checked;
  auto regimes = arguments.get<ffi::AnyBuffer>(K);
  if (!regimes.has_value()) return regimes.error();
  if (regimes->element_type() != ffi::DataType::S32 || regimes->element_count() != count)
    return ffi::Error::InvalidArgument("motion: the regime must be int32 of the result's size");
  const std::int32_t* regime = static_cast<const std::int32_t*>(regimes->untyped_data());
  R* output = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(Order) / 4, [&](std::size_t begin, std::size_t end) {
    if constexpr (Order == 0) {
      // Values: motion.hpp's block, whose straight-line stages are vectorised.
      for (std::size_t i = begin; i < end; i += kBlock) {
        const int block = static_cast<int>(std::min<std::size_t>(kBlock, end - i));
        R in[K][kBlock], values[kMotionOutputs][kBlock];
        for (int j = 0; j < K; ++j)
          for (int p = 0; p < block; ++p) in[j][p] = inputs[j][i + p];
        fill_stand_ins(in, block);
        working_motion_block<R, Attitude>(in, regime + i, block, values);
        for (int p = 0; p < block; ++p)
          for (int o = 0; o < outputs; ++o) output[(i + p) * outputs + o] = values[o][p];
      }
    } else {
      for (std::size_t i = begin; i < end; ++i) {
        R* out = output + i * outputs * W;
        if constexpr (Order == 1) {
          using D = Dual<R, K>;
          D in[K], values[kMotionOutputs];
          for (int j = 0; j < K; ++j) {
            in[j] = D(0.0);
            in[j].v = inputs[j][i];
            in[j].d[j] = R(1);
          }
          working_motion<D>(in, regime[i], Attitude, values);
          for (int o = 0; o < outputs; ++o) {
            out[o * W] = values[o].v;
            for (int j = 0; j < K; ++j) out[o * W + 1 + j] = values[o].d[j];
          }
        } else {
          using D1 = Dual<R, K>;
          using D2 = Dual<D1, K>;
          D2 in[K], values[kMotionOutputs];
          for (int j = 0; j < K; ++j) {
            in[j] = D2(0.0);
            in[j].v.v = inputs[j][i];
            in[j].v.d[j] = R(1);
            in[j].d[j].v = R(1);
          }
          working_motion<D2>(in, regime[i], Attitude, values);
          for (int o = 0; o < outputs; ++o) {
            out[o * W] = values[o].v.v;
            for (int j = 0; j < K; ++j) out[o * W + 1 + j] = values[o].v.d[j];
            for (int j = 0; j < K; ++j)
              for (int k = 0; k < K; ++k) out[o * W + 1 + K + j * K + k] = values[o].d[j].d[k];
          }
        }
      }
    }
  });
  return ffi::Error::Success();
}

template <int Order, bool Attitude>
ffi::Error motion(ffi::ThreadPool pool, ffi::RemainingArgs arguments, ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type("motion", kMotionInputs + 1, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_motion<Order, Attitude, R>(pool, arguments, *result);
  });
}

#define FRBJAX_MOTION_HANDLER(NAME, ORDER, ATTITUDE)                                                 \
  XLA_FFI_DEFINE_HANDLER(NAME##_##ORDER, (motion<ORDER, ATTITUDE>),                                \
                         ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>())

FRBJAX_MOTION_HANDLER(Motion, 0, true);
FRBJAX_MOTION_HANDLER(Motion, 1, true);
FRBJAX_MOTION_HANDLER(Motion, 2, true);
FRBJAX_MOTION_HANDLER(Momentum, 0, false);
FRBJAX_MOTION_HANDLER(Momentum, 1, false);
FRBJAX_MOTION_HANDLER(Momentum, 2, false);

// The whole free flow of bodies with principal moments at one time per point (free_flow.hpp): inputs
// inertia (..., 3), angular momentum (..., 3), attitude (..., 4) and t (...), all of the results' dtype
// and of one batch; results L(t) (..., 3) and q(t) (..., 4).  Values only: frbjax/_free_flow.py takes
// the derivatives of the JAX composite.
template <class R>
ffi::Error run_free_flow(ffi::ThreadPool& pool, const ffi::AnyBuffer& inertia, const ffi::AnyBuffer& momentum,
                         const ffi::AnyBuffer& attitude, const ffi::AnyBuffer& time, ffi::AnyBuffer& momentum_out,
                         ffi::AnyBuffer& attitude_out) {
  const std::size_t count = time.element_count();
  const ffi::DataType dtype = momentum_out.element_type();
  const ffi::AnyBuffer* buffers[] = {&inertia, &momentum, &attitude, &time, &attitude_out};
  for (const ffi::AnyBuffer* buffer : buffers)
    if (buffer->element_type() != dtype)
      return ffi::Error::InvalidArgument("free_flow: every argument and result must have one dtype");
  if (inertia.element_count() != 3 * count || momentum.element_count() != 3 * count ||
      attitude.element_count() != 4 * count || momentum_out.element_count() != 3 * count ||
      attitude_out.element_count() != 4 * count)
    return ffi::Error::InvalidArgument("free_flow: shapes (..., 3), (..., 3), (..., 4), (...) of one batch");
  const R* j = static_cast<const R*>(inertia.untyped_data());
  const R* l = static_cast<const R*>(momentum.untyped_data());
  const R* q = static_cast<const R*>(attitude.untyped_data());
  const R* t = static_cast<const R*>(time.untyped_data());
  R* l_out = static_cast<R*>(momentum_out.untyped_data());
  R* q_out = static_cast<R*>(attitude_out.untyped_data());
  parallel_for(pool, count, grain(0) / 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; i += kBlock) {
      const int block = static_cast<int>(std::min<std::size_t>(kBlock, end - i));
      free_flow_block<R>(j + 3 * i, l + 3 * i, q + 4 * i, t + i, block, l_out + 3 * i, q_out + 4 * i);
    }
  });
  return ffi::Error::Success();
}

ffi::Error free_flow_values(ffi::ThreadPool pool, ffi::AnyBuffer inertia, ffi::AnyBuffer momentum,
                            ffi::AnyBuffer attitude, ffi::AnyBuffer time, ffi::Result<ffi::AnyBuffer> momentum_out,
                            ffi::Result<ffi::AnyBuffer> attitude_out) {
  switch (momentum_out->element_type()) {
    case ffi::DataType::F64:
      return run_free_flow<double>(pool, inertia, momentum, attitude, time, *momentum_out, *attitude_out);
    case ffi::DataType::F32:
      return run_free_flow<float>(pool, inertia, momentum, attitude, time, *momentum_out, *attitude_out);
    default:
      return ffi::Error::InvalidArgument("free_flow: float32 or float64 only");
  }
}

XLA_FFI_DEFINE_HANDLER(FreeFlow, free_flow_values,
                       ffi::Ffi::Bind()
                           .Ctx<ffi::ThreadPool>()
                           .Arg<ffi::AnyBuffer>()
                           .Arg<ffi::AnyBuffer>()
                           .Arg<ffi::AnyBuffer>()
                           .Arg<ffi::AnyBuffer>()
                           .Ret<ffi::AnyBuffer>()
                           .Ret<ffi::AnyBuffer>());

// The free flow's values and partial derivatives (flow_jacobian.hpp): free_flow's inputs, one result
// (..., 7, W): per output (L(t) (3), q(t) (4)) its value, then its derivatives in the moments (3), L0
// (3), q0 (4) and t (Order 1, W = 12), then their derivatives (Order 2, W = 133).
// frbjax/_body.py's JVP rules are products of these with the tangents.
// `Series`: a FreeRigidBody's evaluations (Order 1): series_flow_derivatives, a record per body kept
// over the body's consecutive points.
template <int Order, class R, bool Series = false>
ffi::Error run_free_flow_derivatives(ffi::ThreadPool& pool, const ffi::AnyBuffer& inertia,
                                     const ffi::AnyBuffer& momentum, const ffi::AnyBuffer& attitude,
                                     const ffi::AnyBuffer& time, ffi::AnyBuffer& result) {
  constexpr int W = flow_width<Order>();
  const std::size_t count = time.element_count();
  const ffi::DataType dtype = result.element_type();
  const ffi::AnyBuffer* buffers[] = {&inertia, &momentum, &attitude, &time};
  for (const ffi::AnyBuffer* buffer : buffers)
    if (buffer->element_type() != dtype)
      return ffi::Error::InvalidArgument("free_flow_derivatives: every argument and the result must have one dtype");
  if (inertia.element_count() != 3 * count || momentum.element_count() != 3 * count ||
      attitude.element_count() != 4 * count || result.element_count() != kFlowOutputs * W * count)
    return ffi::Error::InvalidArgument("free_flow_derivatives: shapes (..., 3), (..., 3), (..., 4), (...) -> (..., 7, W)");
  const R* j = static_cast<const R*>(inertia.untyped_data());
  const R* l = static_cast<const R*>(momentum.untyped_data());
  const R* q = static_cast<const R*>(attitude.untyped_data());
  const R* t = static_cast<const R*>(time.untyped_data());
  R* output = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(Order) / 4, [&](std::size_t begin, std::size_t end) {
    SeriesFlow<R> body;
    for (std::size_t i = begin; i < end; i += kBlock) {
      const int block = static_cast<int>(std::min<std::size_t>(kBlock, end - i));
      bool one_time[kBlock], any = false;
      for (int p = 0; p < block; ++p) {
        const std::size_t point = i + p;
        R* out = output + point * kFlowOutputs * W;
        if constexpr (Series) {
          one_time[p] = !series_flow_derivatives<R>(j + 3 * point, l + 3 * point, q + 4 * point, t[point], body, out);
        } else {
          free_flow_derivatives<R, Order>(j + 3 * point, l + 3 * point, q + 4 * point, t[point], out);
          one_time[p] = true;
        }
        any = any || one_time[p];
      }
      if (!any) continue;
      // The one-time motion's values are the values kernel's (free_flow_block): the dual numbers' value
      // parts agree with them to rounding only, its vectorised stages fusing products and sums in other
      // places.
      R momentum_values[3 * kBlock], attitude_values[4 * kBlock];
      free_flow_block<R>(j + 3 * i, l + 3 * i, q + 4 * i, t + i, block, momentum_values, attitude_values);
      for (int p = 0; p < block; ++p) {
        if (!one_time[p]) continue;
        R* out = output + (i + p) * kFlowOutputs * W;
        for (int o = 0; o < 3; ++o) out[o * W] = momentum_values[3 * p + o];
        for (int o = 0; o < 4; ++o) out[(3 + o) * W] = attitude_values[4 * p + o];
      }
    }
  });
  return ffi::Error::Success();
}

template <int Order, bool Series = false>
ffi::Error free_flow_derivative_values(ffi::ThreadPool pool, ffi::AnyBuffer inertia, ffi::AnyBuffer momentum,
                                       ffi::AnyBuffer attitude, ffi::AnyBuffer time, ffi::Result<ffi::AnyBuffer> result) {
  switch (result->element_type()) {
    case ffi::DataType::F64:
      return run_free_flow_derivatives<Order, double, Series>(pool, inertia, momentum, attitude, time, *result);
    case ffi::DataType::F32:
      return run_free_flow_derivatives<Order, float, Series>(pool, inertia, momentum, attitude, time, *result);
    default:
      return ffi::Error::InvalidArgument("free_flow_derivatives: float32 or float64 only");
  }
}

#define FRBJAX_FLOW_DERIVATIVES_HANDLER(NAME, ORDER, SERIES)                                                \
  XLA_FFI_DEFINE_HANDLER(NAME, (free_flow_derivative_values<ORDER, SERIES>),                              \
                         ffi::Ffi::Bind()                                                                 \
                             .Ctx<ffi::ThreadPool>()                                                      \
                             .Arg<ffi::AnyBuffer>()                                                       \
                             .Arg<ffi::AnyBuffer>()                                                       \
                             .Arg<ffi::AnyBuffer>()                                                       \
                             .Arg<ffi::AnyBuffer>()                                                       \
                             .Ret<ffi::AnyBuffer>())

FRBJAX_FLOW_DERIVATIVES_HANDLER(FreeFlow_1, 1, false);
FRBJAX_FLOW_DERIVATIVES_HANDLER(FreeFlow_2, 2, false);
FRBJAX_FLOW_DERIVATIVES_HANDLER(FreeFlowSeries_1, 1, true);

// A FreeRigidBody's records (body.hpp): inertia (..., 3), L0 (..., 3), q0 (..., 4) and optionally the
// principal axes (..., 3, 3), all of the result's dtype and of one batch; the result (..., size).
template <class R>
ffi::Error run_body_record(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  constexpr int size = BodyLayout<R>::size;
  const std::size_t count = result.element_count() / size;
  const bool with_axes = arguments.size() == 4;
  const std::size_t widths[4] = {3, 3, 4, 9};
  const R* inputs[4] = {nullptr, nullptr, nullptr, nullptr};
  if (result.element_count() != count * size) return ffi::Error::InvalidArgument("body_record: wrong result size");
  for (std::size_t j = 0; j < arguments.size(); ++j) {
    auto buffer = arguments.get<ffi::AnyBuffer>(j);
    if (!buffer.has_value()) return buffer.error();
    if (buffer->element_type() != result.element_type() || buffer->element_count() != widths[j] * count)
      return ffi::Error::InvalidArgument("body_record: (..., 3), (..., 3), (..., 4)[, (..., 3, 3)] of the result's dtype");
    inputs[j] = static_cast<const R*>(buffer->untyped_data());
  }
  R* output = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(1) / 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      body_record<R>(inputs[0] + 3 * i, inputs[1] + 3 * i, inputs[2] + 4 * i, with_axes ? inputs[3] + 9 * i : nullptr,
                     output + i * size);
  });
  return ffi::Error::Success();
}

ffi::Error body_record_values(ffi::ThreadPool pool, ffi::RemainingArgs arguments, ffi::Result<ffi::AnyBuffer> result) {
  if (arguments.size() != 3 && arguments.size() != 4)
    return ffi::Error::InvalidArgument("body_record: three or four arguments");
  return by_float_type("body_record", arguments.size(), arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_body_record<R>(pool, arguments, *result);
  });
}

// `evaluate(record, times, count, out)` of records (bodies, size) at times (bodies, per body), each
// body's times contiguous (row-major), in blocks of at most kBlock times of one body: the result
// (..., outputs).  A record is read once per block, not copied per time.  `name` names the kernel in its errors.
template <class R, int Size, int Outputs, class Evaluate>
ffi::Error run_at_times(ffi::ThreadPool& pool, ffi::RemainingArgs& arguments, ffi::AnyBuffer& result,
                        const char* name, Evaluate evaluate) {
  std::size_t count = result.element_count() / Outputs;
  auto records = arguments.get<ffi::AnyBuffer>(0);
  auto times = arguments.get<ffi::AnyBuffer>(1);
  if (!records.has_value()) return records.error();
  if (!times.has_value()) return times.error();
  std::size_t bodies = records->element_count() / Size;
  if (records->element_type() != result.element_type() || times->element_type() != result.element_type() ||
      records->element_count() != bodies * Size || times->element_count() != count ||
      (bodies == 0 ? count != 0 : count % bodies != 0))
    return ffi::Error::InvalidArgument(std::string(name) +
                                       ": records (bodies, size) and times (bodies, ...) of the result's dtype");
  const R* record = static_cast<const R*>(records->untyped_data());
  const R* time = static_cast<const R*>(times->untyped_data());
  R* output = static_cast<R*>(result.untyped_data());
  std::size_t per_body = bodies == 0 ? 0 : count / bodies;
  parallel_for(pool, count, grain(0) / 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end;) {
      const std::size_t body = i / per_body;
      const std::size_t stop = std::min({end, (body + 1) * per_body, i + std::size_t(kBlock)});
      evaluate(record + body * Size, time + i, int(stop - i), output + i * Outputs);
      i = stop;
    }
  });
  return ffi::Error::Success();
}

// A body's state from records (bodies, size) and times t (bodies, per body): (..., 7) (L(t), q(t)) or
// (..., 3) (L(t)).
template <bool Attitude, class R>
ffi::Error run_body_state(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  return run_at_times<R, BodyLayout<R>::size, Attitude ? 7 : 3>(
      pool, arguments, result, "body_state",
      [](const R* record, const R* t, int count, R* out) { body_state_block<R, Attitude>(record, t, count, out); });
}

template <bool Attitude>
ffi::Error body_state_values(ffi::ThreadPool pool, ffi::RemainingArgs arguments, ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type("body_state", 2, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_body_state<Attitude, R>(pool, arguments, *result);
  });
}

XLA_FFI_DEFINE_HANDLER(BodyRecord, body_record_values, ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());
XLA_FFI_DEFINE_HANDLER(BodyState, body_state_values<true>,
                       ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());
XLA_FFI_DEFINE_HANDLER(BodyMomentum, body_state_values<false>,
                       ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());

// For the tests: free_flow.hpp's working frame and regime per body, inertia and angular momentum
// (..., 3) -> (..., 8) (free_flow_frame).
template <class R>
ffi::Error run_free_flow_frame(const ffi::AnyBuffer& inertia, const ffi::AnyBuffer& momentum, ffi::AnyBuffer& result) {
  const std::size_t count = result.element_count() / kFreeFlowFrameOutputs;
  if (inertia.element_type() != result.element_type() || momentum.element_type() != result.element_type() ||
      inertia.element_count() != 3 * count || momentum.element_count() != 3 * count ||
      result.element_count() != kFreeFlowFrameOutputs * count)
    return ffi::Error::InvalidArgument("free_flow_frame: inertia and momentum (..., 3), result (..., 8), one dtype");
  const R* j = static_cast<const R*>(inertia.untyped_data());
  const R* l = static_cast<const R*>(momentum.untyped_data());
  R* out = static_cast<R*>(result.untyped_data());
  for (std::size_t i = 0; i < count; ++i) free_flow_frame<R>(j + 3 * i, l + 3 * i, out + kFreeFlowFrameOutputs * i);
  return ffi::Error::Success();
}

ffi::Error free_flow_frame_values(ffi::AnyBuffer inertia, ffi::AnyBuffer momentum, ffi::Result<ffi::AnyBuffer> result) {
  switch (result->element_type()) {
    case ffi::DataType::F64:
      return run_free_flow_frame<double>(inertia, momentum, *result);
    case ffi::DataType::F32:
      return run_free_flow_frame<float>(inertia, momentum, *result);
    default:
      return ffi::Error::InvalidArgument("free_flow_frame: float32 or float64 only");
  }
}

XLA_FFI_DEFINE_HANDLER(FreeFlowFrame, free_flow_frame_values,
                       ffi::Ffi::Bind().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>());

// A body's series record (series.hpp): inputs J1, J2, J3, l1, l2, l3 and the regime (int32) of one
// size; the result (..., SeriesLayout<R>::size).
template <class R>
ffi::Error run_series_record(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  constexpr int size = SeriesLayout<R>::size;
  const R* inputs[6];
  std::size_t count = result.element_count() / size;
  if (result.element_count() != count * size) return ffi::Error::InvalidArgument("series_record: wrong result size");
  ffi::Error checked = gather<R>(arguments, 6, count, result.element_type(), "series_record", inputs);
  if (checked.failure()) return checked;
  auto regimes = arguments.get<ffi::AnyBuffer>(6);
  if (!regimes.has_value()) return regimes.error();
  if (regimes->element_type() != ffi::DataType::S32 || regimes->element_count() != count)
    return ffi::Error::InvalidArgument("series_record: the regime must be int32 of the bodies' size");
  const std::int32_t* regime = static_cast<const std::int32_t*>(regimes->untyped_data());
  R* output = static_cast<R*>(result.untyped_data());
  parallel_for(pool, count, grain(1) / 4, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      R in[6];
      for (int j = 0; j < 6; ++j) in[j] = inputs[j][i];
      series_record<R>(in, regime[i], output + i * size);
    }
  });
  return ffi::Error::Success();
}

// The motion from records (bodies, size) and times (bodies, per body), each body's times contiguous
// (row-major): (bodies, per body, 7) or (..., 3).
template <bool Attitude, class R>
ffi::Error run_series_motion(ffi::ThreadPool& pool, ffi::RemainingArgs arguments, ffi::AnyBuffer& result) {
  return run_at_times<R, SeriesLayout<R>::size, Attitude ? 7 : 3>(
      pool, arguments, result, "series_motion",
      [](const R* record, const R* tau, int count, R* out) { series_motion_rows<R, Attitude>(record, tau, count, out); });
}

ffi::Error series_record_values(ffi::ThreadPool pool, ffi::RemainingArgs arguments,
                                ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type("series_record", 7, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_series_record<R>(pool, arguments, *result);
  });
}

template <bool Attitude>
ffi::Error series_motion_values(ffi::ThreadPool pool, ffi::RemainingArgs arguments,
                                ffi::Result<ffi::AnyBuffer> result) {
  return by_float_type("series_motion", 2, arguments, *result, [&](auto zero) {
    using R = decltype(zero);
    return run_series_motion<Attitude, R>(pool, arguments, *result);
  });
}

XLA_FFI_DEFINE_HANDLER(SeriesRecord, series_record_values, ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());
XLA_FFI_DEFINE_HANDLER(SeriesMotion, series_motion_values<true>,
                       ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());
XLA_FFI_DEFINE_HANDLER(SeriesMomentum, series_motion_values<false>,
                       ffi::Ffi::Bind().Ctx<ffi::ThreadPool>().RemainingArgs().Ret<ffi::AnyBuffer>());

struct Entry {
  const char* name;
  XLA_FFI_Handler* handler;
};

const Entry kHandlers[] = {
    {"frbjax_elliprf_0", Rf_0}, {"frbjax_elliprf_1", Rf_1}, {"frbjax_elliprf_2", Rf_2},
    {"frbjax_elliprd_0", Rd_0}, {"frbjax_elliprd_1", Rd_1}, {"frbjax_elliprd_2", Rd_2},
    {"frbjax_elliprj_0", Rj_0}, {"frbjax_elliprj_1", Rj_1}, {"frbjax_elliprj_2", Rj_2},
    {"frbjax_elliprc_0", Rc_0}, {"frbjax_elliprc_1", Rc_1}, {"frbjax_elliprc_2", Rc_2},
    {"frbjax_ellipj_0", Ellipj_0},
    {"frbjax_motion_0", Motion_0},     {"frbjax_motion_1", Motion_1},     {"frbjax_motion_2", Motion_2},
    {"frbjax_series_record", SeriesRecord}, {"frbjax_series_motion", SeriesMotion},
    {"frbjax_series_momentum", SeriesMomentum},
    {"frbjax_momentum_0", Momentum_0}, {"frbjax_momentum_1", Momentum_1}, {"frbjax_momentum_2", Momentum_2},
    {"frbjax_free_flow", FreeFlow},    {"frbjax_free_flow_1", FreeFlow_1}, {"frbjax_body_record", BodyRecord}, {"frbjax_body_state", BodyState}, {"frbjax_body_momentum", BodyMomentum}, {"frbjax_free_flow_2", FreeFlow_2}, {"frbjax_free_flow_series_1", FreeFlowSeries_1},    {"frbjax_free_flow_frame", FreeFlowFrame},
};

PyObject* handlers(PyObject*, PyObject*) {
  PyObject* table = PyDict_New();
  if (table == nullptr) return nullptr;
  for (const Entry& entry : kHandlers) {
    PyObject* capsule = PyCapsule_New(reinterpret_cast<void*>(entry.handler), nullptr, nullptr);
    if (capsule == nullptr || PyDict_SetItemString(table, entry.name, capsule) != 0) {
      Py_XDECREF(capsule);
      Py_DECREF(table);
      return nullptr;
    }
    Py_DECREF(capsule);
  }
  return table;
}

#ifndef FRBJAX_JAXLIB_VERSION
#define FRBJAX_JAXLIB_VERSION "unknown"
#endif

PyObject* jaxlib_version(PyObject*, PyObject*) { return PyUnicode_FromString(FRBJAX_JAXLIB_VERSION); }

// Whether this CPU has fused multiply-add instructions, for choosing the FMA build (CMakeLists.txt).
PyObject* cpu_has_fma(PyObject*, PyObject*) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_cpu_init();
  return PyBool_FromLong(__builtin_cpu_supports("fma") ? 1 : 0);
#else
  Py_RETURN_FALSE;
#endif
}

PyMethodDef kMethods[] = {
    {"handlers", handlers, METH_NOARGS, "{target name: PyCapsule of the XLA FFI handler}."},
    {"jaxlib_version", jaxlib_version, METH_NOARGS, "The jaxlib whose XLA FFI headers the kernels were built with."},
    {"cpu_has_fma", cpu_has_fma, METH_NOARGS, "Whether this CPU has FMA instructions (the FMA build runs here)."},
    {nullptr, nullptr, 0, nullptr},
};

// Two builds of this file (CMakeLists.txt): _kernels for any CPU of the target, _kernels_fma with FMA
// instructions and the motion's products fused (motion.hpp), chosen at run time where the CPU has them.
#ifndef FRBJAX_MODULE
#define FRBJAX_MODULE _kernels
#endif
#define FRBJAX_STRING_OF(x) #x
#define FRBJAX_STRING(x) FRBJAX_STRING_OF(x)
#define FRBJAX_JOIN_OF(a, b) a##b
#define FRBJAX_JOIN(a, b) FRBJAX_JOIN_OF(a, b)

PyModuleDef kModule = {PyModuleDef_HEAD_INIT, FRBJAX_STRING(FRBJAX_MODULE), "frbjax's compiled CPU kernels (XLA FFI).", -1,
                       kMethods};

}  // namespace
}  // namespace frbjax

PyMODINIT_FUNC FRBJAX_JOIN(PyInit_, FRBJAX_MODULE)() { return PyModule_Create(&frbjax::kModule); }
