r"""The compiled CPU kernels of the special functions (``frbjax._kernels``, C++ behind XLA's FFI):
Carlson's R_F, R_D, R_J, R_C with their derivatives, and Jacobi's sn, cn, dn, am (whose JVP rule is
written in ``_jacobi.py`` with these values and the R_D kernel).

The C++ core (``csrc/``) evaluates each function with one scalar implementation, templated on the
number type, per point with its own stopping rule (the algorithms of the JAX path, which stays for
accelerators and as the cross-check).  A call costs XLA a custom call to compile, whatever the
arithmetic inside, where the JAX path's unrolled duplications and AGM steps compile to many kernels.

Which path runs is decided where a public function is traced (``selected``): the kernels when the
default backend is the CPU, the extension was built at install, the dtype is float32 or float64, and
``FRBJAX_KERNELS`` is not ``jax``; the JAX path otherwise.  ``FRBJAX_KERNELS=compiled`` makes a
missing extension an error instead of a warning.

Derivatives: the kernels also evaluate the function on dual numbers, which gives its partial
derivatives (order 1) and second partial derivatives (order 2) from the same code.  Every duplication
step is an exact identity, so the derivative of the algorithm converges to the derivative of the
function (DLMF 19.26.18-19.26.20).  The JVP rules are linear in the tangents, so that reverse mode
transposes a product, never a loop; second derivatives come from the rule of the order-1 kernel.
Third derivatives are not provided (JAX reports the missing rule).  The zero-argument convention of
the JAX path holds: the tangent of an argument that is exactly zero, where the partial derivative is
infinite, is ignored (``frbjax.special._carlson``'s module note).
"""

from __future__ import annotations

import functools
import importlib.metadata
import itertools
import os
import warnings
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import jax
import jax.numpy as jnp

from ._common import real_array


_SWITCH = "FRBJAX_KERNELS"
P = ParamSpec("P")
R = TypeVar("R")


@functools.cache
def _module():
    """The extension module, or None where it was not built (a warning, once)."""
    try:
        from .. import _kernels
    except ImportError as error:
        if os.environ.get(_SWITCH) == "compiled":
            raise ImportError(f"{_SWITCH}=compiled but frbjax's compiled kernels were not built: {error}") from error
        warnings.warn(
            f"frbjax's compiled CPU kernels were not built at install ({error}); the JAX path runs on the "
            "CPU too (slower to compile).  Reinstall with a C++17 compiler to build them.",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    # Handlers built with a newer jaxlib's FFI headers than the one running cannot be registered, and
    # a failed registration stops JAX's CPU backend from starting: check first (pip builds with the
    # newest jaxlib unless the build is constrained too).
    built, running = _kernels.jaxlib_version(), importlib.metadata.version("jaxlib")
    if _release(running) < _release(built):
        message = (
            f"frbjax's compiled kernels were built with jaxlib {built}, newer than the jaxlib {running} that "
            "runs; the JAX path runs on the CPU too.  Reinstall frbjax with this jaxlib in the build "
            "(pip install --no-build-isolation, or PIP_CONSTRAINT) to use them."
        )
        if os.environ.get(_SWITCH) == "compiled":
            raise ImportError(f"{_SWITCH}=compiled but {message}")
        warnings.warn(message, RuntimeWarning, stacklevel=3)
        return None
    module = _kernels
    if _kernels.cpu_has_fma():
        # The FMA build (CMakeLists.txt), as XLA:CPU compiles the JAX path with FMA instructions here.
        try:
            from .. import _kernels_fma as module
        except ImportError:
            module = _kernels
    for name, capsule in module.handlers().items():
        jax.ffi.register_ffi_target(name, capsule, platform="cpu")
    return module


def _release(version):
    """The numeric release of a version string ("0.10.2" -> (0, 10, 2)); () where unknown."""
    numbers = []
    for part in version.split("."):
        digits = "".join(itertools.takewhile(str.isdigit, part))
        if not digits:
            break
        numbers.append(int(digits))
    return tuple(numbers)


def keyed_jit(function, key, *, jit=jax.jit, **jit_options):
    """``jit(function, **jit_options)`` made once per value of ``key()`` (read at each call) and called
    for the current one: the compiled kernels or the JAX formulas are chosen when a function is traced,
    from environment variables, which jit's cache does not know.  Each value gets its own copy of the
    function: jit shares one trace between every jit of the same function object (jax 0.10), so a
    second jit of ``function`` itself would reuse the first's trace.  ``jit`` is ``jax.jit`` or
    ``equinox.filter_jit``."""

    @functools.cache
    def program(value):
        del value  # the cache's key only: the copy reads the variables when it is traced

        @functools.wraps(function)
        def copy(*args, **kwargs):
            return function(*args, **kwargs)

        return jit(copy, **jit_options)

    @functools.wraps(function)
    def call(*args, **kwargs):
        return program(key())(*args, **kwargs)

    return call


def _path():
    return os.environ.get(_SWITCH, "auto")


def one_program(function: Callable[P, R]) -> Callable[P, R]:
    """A public special function as one compiled program per argument types and path.

    Called eagerly, the function's hundreds of operations ran one by one (``ellippiinc`` of 21 points:
    0.56 s a call, 1.89 s the first; compiled once: 83 µs a call, 1.22 s the first; one core,
    benchmarks/special_eager.py), where a ``jax.numpy`` function or a FreeRigidBody method is one program.
    The path is read from ``FRBJAX_KERNELS`` at each call and keys the compiled program, so that a
    change of the variable takes effect at the next call, as before.  Inside a caller's ``jit``,
    ``vmap`` or ``grad`` the function is traced inline like any other.
    """

    program = keyed_jit(function, _path)

    @functools.wraps(function)
    def call(*args: P.args, **kwargs: P.kwargs) -> R:
        # Arguments that are not real numbers are refused here, with the message of the function's own
        # check: jit would refuse a string with a TypeError of its own before the function runs.
        arrays = [real_array(a) for a in args]
        keywords = {name: None if a is None else real_array(a) for name, a in kwargs.items()}
        return program(*arrays, **keywords)

    return call


def selected(*arrays) -> bool:
    """Whether the compiled kernels evaluate a function of ``arrays`` (decided when it is traced)."""
    choice = os.environ.get(_SWITCH, "auto")
    if choice not in ("auto", "compiled", "jax"):
        raise ValueError(f"{_SWITCH} must be 'auto', 'compiled' or 'jax', got {choice!r}")
    if choice == "jax" or jax.default_backend() != "cpu":
        return False
    if any(jnp.result_type(a) not in (jnp.float32, jnp.float64) for a in arrays):
        return False
    return _module() is not None


def _width(arity, order):
    return (1, 1 + arity, 1 + arity + arity * arity)[order]


def call(name, order, arguments, width=None):
    """The kernel ``name`` of ``order`` (0, 1, 2) on broadcast arguments: (..., width), ``width`` by
    default that of a scalar function and its derivatives."""
    first = arguments[0]
    width = _width(len(arguments), order) if width is None else width
    shape = jax.ShapeDtypeStruct(first.shape + (width,), first.dtype)
    return jax.ffi.ffi_call(f"frbjax_{name}_{order}", shape, vmap_method="broadcast_all")(*arguments)


def _masked_tangents(primals, tangents, may_vanish):
    """The tangents stacked on a last axis, those of exactly-zero arguments at ``may_vanish`` set to 0."""
    columns = []
    for index, (primal, tangent) in enumerate(zip(primals, tangents)):
        tangent = jnp.broadcast_to(tangent, primal.shape)
        columns.append(jnp.where(primal > 0, tangent, 0) if index in may_vanish else tangent)
    return jnp.stack(columns, axis=-1)


def differentiable(kernel, inputs, direction):
    """(function, with_partials): a compiled kernel as a JAX function with its derivatives.

    ``kernel(order, arguments)`` gives (..., outputs, width): each output's value, then (order >= 1)
    its partials in the ``inputs`` differentiable arguments, then (order 2) their second partials;
    ``direction(primals, tangents)`` gives the tangents of those arguments stacked on a last axis
    (..., inputs).  ``function(*arguments)`` is (..., outputs) (order-0 kernel); its JVP is the
    order-1 kernel's partials times the tangents, linear in them, so reverse mode transposes it;
    ``with_partials(*arguments)`` gives (value, partials) and its own JVP from the order-2 kernel:
    second derivatives, no third.
    """

    @jax.custom_jvp
    def with_partials(*arguments):
        out = kernel(1, arguments)
        return out[..., 0], out[..., 1:]

    @with_partials.defjvp
    def with_partials_jvp(primals, tangents):
        out = kernel(2, primals)
        value, partials = out[..., 0], out[..., 1 : 1 + inputs]
        second = out[..., 1 + inputs :].reshape(out.shape[:-1] + (inputs, inputs))
        step = direction(primals, tangents)[..., None, :]
        return (value, partials), (
            jnp.sum(partials * step, axis=-1),
            jnp.sum(second * step[..., None, :], axis=-1),
        )

    @jax.custom_jvp
    def function(*arguments):
        return kernel(0, arguments)[..., 0]

    @function.defjvp
    def function_jvp(primals, tangents):
        value, partials = with_partials(*primals)
        return value, jnp.sum(partials * direction(primals, tangents)[..., None, :], axis=-1)

    return function, with_partials


def _elementwise(name, arity, may_vanish):
    """``name``'s compiled kernel as a JAX function of ``arity`` broadcast arrays, with its derivatives."""
    function, _ = differentiable(
        lambda order, arguments: call(name, order, arguments)[..., None, :],
        arity,
        lambda primals, tangents: _masked_tangents(primals, tangents, may_vanish),
    )

    def scalar(*arguments):
        return function(*arguments)[..., 0]

    scalar.__name__ = name
    return scalar


# The positions of the arguments that may be exactly zero (their tangents are ignored there).
elliprf = _elementwise("elliprf", 3, (0, 1, 2))
elliprd = _elementwise("elliprd", 3, (0, 1))
elliprj = _elementwise("elliprj", 4, (0, 1, 2))
elliprc = _elementwise("elliprc", 2, (0,))
