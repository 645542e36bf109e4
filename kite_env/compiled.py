"""The compiled backend: the one module of the package that imports numba.

The compiled kernels live next to the code they compute (the structural elements' in
``kite_env/structure/*_kernels.py``, the section loads' in :mod:`kite_env.aero.kernels`, the particle system's in
:mod:`kite_env.dynamics.kernels`, the batched kites' in :mod:`kite_env.dynamics.fast`, the observation's in
:mod:`kite_env.envs.observe`, the wind's mode sum in :mod:`kite_env.wind`); they take :func:`njit` from here and,
but for the wind's mode sum (its own ``fastmath`` flags), the options :data:`JIT`; the classes that hold a backend
choose it with :func:`resolve_backend`.

Backends
--------
The element sets take ``backend="auto" | "numba" | "numpy"`` (see :func:`resolve_backend`).  ``"auto"`` picks
the value of the environment variable ``KITE_ENV_ELEMENT_BACKEND`` if set, else ``"numba"`` when numba can be
imported, else ``"numpy"``.  Without numba the kernels are plain Python (correct but very slow; only useful for
debugging), and ``"numba"`` raises.

Compilation and cost
--------------------
``cache=True``: the machine code is cached in ``__pycache__`` next to the file that defines a kernel, so only the
first process after a change of that file compiles (~30 s for the beam and shell kernels on the shared 2-core
development container; later processes load the cache in ~0.5 s).  ``fastmath=False``: IEEE semantics, no
reassociation or FMA contraction.  Measured on that container (best of repeats, rhino16 mesh):
``ShellSet.internal`` 360 triangles ~0.6 ms (NumPy ~8-9 ms), ``BeamSet.internal`` 107 beams ~0.18 ms (NumPy
~3.7 ms).

numba's on-disk cache is keyed on the file that defines a function: it does not see a change in an ``njit`` helper
that the function calls from another file (numba documentation, "Cache limitations"), and a process would then load
the caller compiled with the old helper.  The element kernels call the shared helpers of
:mod:`kite_env.structure.rotation_kernels`; they are tested against their NumPy references
(``tests/structure/test_kernels.py``), which catches such a stale helper, and a developer who edits a shared helper
clears ``__pycache__`` (e.g. ``find kite_env -name __pycache__ -exec rm -r {} +``).  For the same reason the kernels'
thresholds are literals in the kernel's own file, not imports, with a test that they equal the reference values.

Implementation rule: inside the element loops no array view (``a[e]``, ``a[k]``) is taken and no array is passed
to a helper function.  In numba each of these costs two atomic reference-count updates, which were measured to
take a large share of the run time; helpers therefore take and return scalars (tuples).  Outputs are written into
arrays supplied by the caller; scratch arrays are allocated once per call.
"""

from __future__ import annotations

import os

try:  # numba is a declared dependency; the fallback keeps the package importable without it
    from numba import njit
    from numba.core import types as _types
    from numba.extending import intrinsic

    NUMBA_AVAILABLE = True

    @intrinsic
    def fma(typingctx, a, b, c):
        """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``: the FMA instruction where the CPU has one, a correctly
        rounded library call where not), for kernels that must give what an FMA kernel of OpenBLAS gives; kernels
        only (``fastmath=False`` contracts nothing by itself)."""
        sig = _types.float64(_types.float64, _types.float64, _types.float64)

        def codegen(context, builder, signature, args):
            return builder.fma(*args)

        return sig, codegen
except ImportError:  # pragma: no cover - exercised only in environments without numba
    NUMBA_AVAILABLE = False

    def njit(*_args, **_kwargs):
        """Identity decorator used when numba is missing (kernels run as plain Python)."""
        return lambda fun: fun

    def fma(a, b, c):
        """``a * b + c`` rounded once (exact rational arithmetic; non-finite operands as the unfused form)."""
        import math
        from fractions import Fraction

        if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
            return a * b + c
        return float(Fraction(a) * Fraction(b) + Fraction(c))


BACKENDS = ("auto", "numba", "numpy")
ENV_VAR = "KITE_ENV_ELEMENT_BACKEND"
# ``error_model="numpy"`` (as the dynamics' kernels): a division by zero (a degenerate triangle, a beam of zero
# length in a Newton iterate) gives ``inf``/``nan`` as the NumPy reference does, which the solver reports as a
# non-finite residual (a failed step, made again in halves), instead of raising ``ZeroDivisionError`` out of the
# flight (seen with the von Karman canopy folding, docs/steering.md, "The von Karman membrane")
JIT = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")


def resolve_backend(backend: str = "auto") -> str:
    """Return ``"numba"`` or ``"numpy"`` for a requested ``backend`` (``"auto"``, ``"numba"``, ``"numpy"``).

    ``"auto"``: the environment variable ``KITE_ENV_ELEMENT_BACKEND`` (``numba``/``numpy``) if set, else numba when
    it is importable.  Raises ``ValueError`` for an unknown name and ``ImportError`` for ``"numba"`` without numba.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        env = os.environ.get(ENV_VAR, "").strip().lower()
        if env in ("numba", "numpy"):
            backend = env
        elif env not in ("", "auto"):
            raise ValueError(f"{ENV_VAR}={env!r}: expected 'numba', 'numpy' or 'auto'")
        else:
            backend = "numba" if NUMBA_AVAILABLE else "numpy"
    if backend == "numba" and not NUMBA_AVAILABLE:
        raise ImportError("backend='numba' requested but numba is not installed")
    return backend
