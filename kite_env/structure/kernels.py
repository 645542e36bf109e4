"""Compiled (numba) element kernels: internal force, tangent and energy of beams and shell triangles.

These functions compute the same quantities as the NumPy reference implementations
(:meth:`kite_env.structure.beam.BeamSet.internal`, :meth:`kite_env.structure.shell.ShellSet.internal` with
:mod:`.shell_membrane` and :mod:`.shell_bending`), term by term and with the same branch thresholds (series
expansions of the rotation functions, wrinkling states with ``TAUT_TOL``), as one compiled loop over the
elements; the results agree with NumPy to round-off (``tests/structure/test_kernels.py``: 1e-10 relative, observed
~1e-15).  The reference code is vectorised over elements with ``np.einsum``; at the size of the kite mesh (360
triangles, 107 beams) it is dominated by the overhead of several hundred NumPy calls on small arrays.  The
derivations are in the docstrings of the reference modules and are not repeated here; comments name the
reference quantity each block computes.  A few products are regrouped for speed (symmetric ``B^T D B``,
``Q^T K_l Q`` as ``Q^T (K_l Q)``, reciprocals instead of repeated divisions), which changes only round-off.

Backends
--------
The element sets take ``backend="auto" | "numba" | "numpy"`` (see :func:`resolve_backend`).  ``"auto"`` picks
the value of the environment variable ``KITE_ENV_ELEMENT_BACKEND`` if set, else ``"numba"`` when numba can be
imported, else ``"numpy"``.  Without numba the kernels below are plain Python (correct but very slow; only
useful for debugging), and ``"numba"`` raises.

Compilation and cost
--------------------
``cache=True``: the machine code is cached in ``__pycache__`` next to this file, so only the first process after
a change of this file compiles (~30 s for both kernels on the shared 2-core development container; later
processes load the cache in ~0.5 s).  ``fastmath=False``: IEEE semantics, no reassociation or FMA contraction.
Measured on that container (best of repeats, rhino16 mesh): ``ShellSet.internal`` 360 triangles ~0.6 ms
(NumPy ~8-9 ms), ``BeamSet.internal`` 107 beams ~0.18 ms (NumPy ~3.7 ms).

Implementation rule: inside the element loops no array view (``a[e]``, ``a[k]``) is taken and no array is passed
to a helper function.  In numba each of these costs two atomic reference-count updates, which were measured to
take a large share of the run time; helpers therefore take and return scalars (tuples).  Outputs are written into
arrays supplied by the caller; scratch arrays are allocated once per call.
"""

from __future__ import annotations

import math
import os

import numpy as np

from .tube import _FOLD_LINEAR  # the fold contact's linear continuation (a compile-time constant here)

try:  # numba is a declared dependency; the fallback keeps the package importable without it
    from numba import njit

    NUMBA_AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only in environments without numba
    NUMBA_AVAILABLE = False

    def njit(*_args, **_kwargs):
        """Identity decorator used when numba is missing (kernels run as plain Python)."""
        return lambda fun: fun


BACKENDS = ("auto", "numba", "numpy")
ENV_VAR = "KITE_ENV_ELEMENT_BACKEND"
# ``error_model="numpy"`` (as the dynamics' kernels): a division by zero (a degenerate triangle, a beam of zero
# length in a Newton iterate) gives ``inf``/``nan`` as the NumPy reference does, which the solver reports as a
# non-finite residual (a failed step, made again in halves), instead of raising ``ZeroDivisionError`` out of the
# flight (seen with the von Karman canopy folding, docs/steering.md, "The von Karman membrane")
_JIT = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")

# Thresholds of the reference implementations.  Literals, not imports: numba's cache is keyed on this file only,
# so a changed import would not recompile; tests/structure/test_kernels.py checks that they stay equal.
_ROT_SMALL = 1e-6  # rotations.logm: series of the angle/sin factor
_TINV_SMALL = 1e-4  # rotations.tangent_inv: series of eta and c
_TSMALL = 0.2  # beam._tinv_derivative_coeffs: series of eta'/t and c'/t
_LOGROT_SMALL = 1e-4  # shell_bending._log_rotation: series of atan2(s, c)/s
_LOGROT_FAR = 1e-3  # shell_bending._log_rotation: cos(t) below this -> quaternion logm
_TAUT_TOL = 1e-12  # shell_membrane.TAUT_TOL
_WRINKLE_MAX_ITER = 30  # shell_membrane._WRINKLE_MAX_ITER
_WRINKLE_MAX_STEP = 0.3  # shell_membrane._WRINKLE_MAX_STEP
_WRINKLE_STEP_TOL = 1e-13  # shell_membrane._WRINKLE_STEP_TOL


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


# ============================================================================================ small helpers
# Implementation note: the element loops never take array views (``a[e]``, ``a[k]``) and never pass views to
# helpers; each view costs two atomic reference-count updates in numba, which were measured to dominate the
# run time.  Helpers therefore take whole arrays plus indices, or scalars, and return tuples.
@njit(**_JIT)
def _cross(u0, u1, u2, v0, v1, v2):
    """Cross product of two 3-vectors given by components; returns a tuple."""
    return u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0


@njit(**_JIT)
def _quat_logm(R00, R01, R02, R10, R11, R12, R20, R21, R22):
    """``rotations.logm`` of one rotation matrix given by its entries (Shepperd's quaternion, then the angle)."""
    tr = R00 + R11 + R22
    k = 0  # first maximum of [tr, R00, R11, R22], as np.argmax
    best = tr
    if R00 > best:
        k, best = 1, R00
    if R11 > best:
        k, best = 2, R11
    if R22 > best:
        k = 3
    if k == 0:
        s = math.sqrt(max(1.0 + tr, 1e-300)) * 2.0
        q0, q1, q2, q3 = 0.25 * s, (R21 - R12) / s, (R02 - R20) / s, (R10 - R01) / s
    elif k == 1:
        s = math.sqrt(max(1.0 + R00 - R11 - R22, 1e-300)) * 2.0
        q0, q1, q2, q3 = (R21 - R12) / s, 0.25 * s, (R01 + R10) / s, (R02 + R20) / s
    elif k == 2:
        s = math.sqrt(max(1.0 - R00 + R11 - R22, 1e-300)) * 2.0
        q0, q1, q2, q3 = (R02 - R20) / s, (R01 + R10) / s, 0.25 * s, (R12 + R21) / s
    else:
        s = math.sqrt(max(1.0 - R00 - R11 + R22, 1e-300)) * 2.0
        q0, q1, q2, q3 = (R10 - R01) / s, (R02 + R20) / s, (R12 + R21) / s, 0.25 * s
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    qn = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    w, v0, v1, v2 = q0 / qn, q1 / qn, q2 / qn, q3 / qn
    sv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if sv < _ROT_SMALL:
        wm = max(w, 1e-300)
        fac = 2.0 / wm * (1.0 - sv**2 / (3.0 * wm**2))
    else:
        fac = 2.0 * math.atan2(sv, w) / sv
    return fac * v0, fac * v1, fac * v2


@njit(**_JIT)
def relative_rotation_vectors(R1, R0, out):
    """``out[k] = rotations.logm(R1[k] @ R0[k].T)`` for (n, 3, 3) rotations ``R1``, ``R0`` into ``out`` (n, 3) [rad]:
    each node's spatial rotation vector from ``R0`` to ``R1`` (the wing's rotations over a time step)."""
    for k in range(R1.shape[0]):
        a00 = R1[k, 0, 0] * R0[k, 0, 0] + R1[k, 0, 1] * R0[k, 0, 1] + R1[k, 0, 2] * R0[k, 0, 2]
        a01 = R1[k, 0, 0] * R0[k, 1, 0] + R1[k, 0, 1] * R0[k, 1, 1] + R1[k, 0, 2] * R0[k, 1, 2]
        a02 = R1[k, 0, 0] * R0[k, 2, 0] + R1[k, 0, 1] * R0[k, 2, 1] + R1[k, 0, 2] * R0[k, 2, 2]
        a10 = R1[k, 1, 0] * R0[k, 0, 0] + R1[k, 1, 1] * R0[k, 0, 1] + R1[k, 1, 2] * R0[k, 0, 2]
        a11 = R1[k, 1, 0] * R0[k, 1, 0] + R1[k, 1, 1] * R0[k, 1, 1] + R1[k, 1, 2] * R0[k, 1, 2]
        a12 = R1[k, 1, 0] * R0[k, 2, 0] + R1[k, 1, 1] * R0[k, 2, 1] + R1[k, 1, 2] * R0[k, 2, 2]
        a20 = R1[k, 2, 0] * R0[k, 0, 0] + R1[k, 2, 1] * R0[k, 0, 1] + R1[k, 2, 2] * R0[k, 0, 2]
        a21 = R1[k, 2, 0] * R0[k, 1, 0] + R1[k, 2, 1] * R0[k, 1, 1] + R1[k, 2, 2] * R0[k, 1, 2]
        a22 = R1[k, 2, 0] * R0[k, 2, 0] + R1[k, 2, 1] * R0[k, 2, 1] + R1[k, 2, 2] * R0[k, 2, 2]
        out[k, 0], out[k, 1], out[k, 2] = _quat_logm(a00, a01, a02, a10, a11, a12, a20, a21, a22)
    return out


@njit(**_JIT)
def _log_rotation(R00, R01, R02, R10, R11, R12, R20, R21, R22):
    """``shell_bending._log_rotation`` of one rotation matrix given by its entries: axis-angle formula, quaternion
    ``logm`` when ``cos t < 1e-3``."""
    v0 = 0.5 * (R21 - R12)
    v1 = 0.5 * (R02 - R20)
    v2 = 0.5 * (R10 - R01)
    s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)  # sin(t)
    c = 0.5 * (R00 + R11 + R22 - 1.0)  # cos(t)
    if c < _LOGROT_FAR:
        return _quat_logm(R00, R01, R02, R10, R11, R12, R20, R21, R22)
    if s < _LOGROT_SMALL:
        fac = 1.0 + s**2 / 6.0
    else:
        fac = math.atan2(s, c) / s
    return fac * v0, fac * v1, fac * v2


@njit(**_JIT)
def _tinv_coeffs(t2):
    """Scalar coefficients of ``T_s^{-1}(theta)`` and of ``d(T_s^{-T}(theta) m)/d theta`` for ``t2 = |theta|^2``.

    Returns ``(eta, c_T, detat, dct, c_D)`` with::

        T_s^{-1} = eta I + c_T theta theta^T - [theta]x / 2                    (rotations.tangent_inv)
        d(T_s^{-T} m)/d theta = detat m theta^T + (theta.m) dct theta theta^T
                                + c_D ((theta.m) I + theta m^T) + [m]x / 2       (beam._dTinvT_m)

    ``eta = (t/2) / tan(t/2)``, ``c = (1 - eta) / t^2``, ``detat = eta'(t)/t``, ``dct = c'(t)/t``, with the Taylor
    series and thresholds of the reference functions (``tan(t/2)`` is evaluated once for both).
    """
    t = math.sqrt(t2)
    half = 0.5 * t
    tan_h = math.tan(half) if t >= _TINV_SMALL else 1.0
    if t < _TINV_SMALL:
        eta = 1.0 - t2 / 12.0
        c_T = 1.0 / 12.0 + t2 / 720.0
    else:
        eta = half / tan_h
        c_T = (1.0 - eta) / t**2
    if t < _TSMALL:
        detat = -(1.0 / 6.0 + t2 / 180.0 + t2**2 / 5040.0 + t2**3 / 151200.0 + t2**4 / 4790016.0)
        dct = 1.0 / 360.0 + t2 / 7560.0 + t2**2 / 201600.0 + t2**3 / 5987520.0
        c_D = 1.0 / 12.0 + t2 / 720.0 + t2**2 / 30240.0 + t2**3 / 1209600.0 + t2**4 / 47900160.0
    else:
        deta = 0.5 / tan_h - t / (4.0 * math.sin(half) ** 2)
        detat = deta / t
        c_D = (1.0 - eta) / t**2
        dct = (-deta / t**2 - 2.0 * c_D / t) / t
    return eta, c_T, detat, dct, c_D


@njit(**_JIT)
def beam_local_rotations(x_e, R_e, R0, l_out, th_out):
    """Chord length and local end rotations of co-rotational beams, as ``BeamSet._frame`` (``l``, ``theta``).

    x_e : (n, 2, 3), R_e : (n, 2, 3, 3), R0 : (n, 3, 3) as :func:`beam_internal`; outputs ``l_out`` (n,) [m] and
    ``th_out`` (n, 2, 3) [rad] (overwritten). Used for the inflated-tube secant stiffness once per iteration.
    """
    n = x_e.shape[0]
    r1, r2, r3, q, tmp3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    qn = np.empty((2, 3))
    Rr, Rb, tmp = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for e in range(n):
        for i in range(3):
            tmp3[i] = x_e[e, 1, i] - x_e[e, 0, i]
        l = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        l_out[e] = l
        for i in range(3):
            r1[i] = tmp3[i] / l
        for k in range(2):
            for i in range(3):
                qn[k, i] = R_e[e, k, i, 0] * R0[e, 0, 1] + R_e[e, k, i, 1] * R0[e, 1, 1] + R_e[e, k, i, 2] * R0[e, 2, 1]
        for i in range(3):
            q[i] = 0.5 * (qn[0, i] + qn[1, i])
        tmp3[0], tmp3[1], tmp3[2] = _cross(r1[0], r1[1], r1[2], q[0], q[1], q[2])
        nn3 = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        for i in range(3):
            r3[i] = tmp3[i] / nn3
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        for k in range(2):
            for i in range(3):
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th_out[e, k, 0], th_out[e, k, 1], th_out[e, k, 2] = _quat_logm(
                Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2], Rb[2, 0], Rb[2, 1], Rb[2, 2])


#: below this normalised curvature / twist the material tangent terms of the secant law are 0 (m = 0 there)
_SECANT_TINY = 1e-12


@njit(**_JIT)
def tube_secants(th, L0, rows, EI0, M_max, kappa_collapse, GJ0, c2, kappa_fold, kappa_closed, energy, with_tangent,
                 EI_out, GJ_out, collapsed_out, gb_out, gt_out):
    """Breukels' secant tube stiffnesses from the local end rotations (``AeroelasticWing.update_tube_stiffness``).

    th : (n_beams, 2, 3) float [rad], L0 : (n_beams,) float [m]   local end rotations (:func:`beam_local_rotations`)
    and the lengths the curvatures are per (unloaded for ``energy``, the current chord for the larger-end law);
    rows : (n_tube,) int   the tube beams; EI0, M_max, kappa_collapse, GJ0, c2, kappa_fold,
    kappa_closed : (n_tube,) float   :class:`kite_env.structure.tube.TubeProperties` (the fold contact of
    :func:`kite_env.structure.tube.fold_contact` where ``kappa_fold`` is finite); energy : bool   the curvature
    measure, True: the element's root-mean-square curvature ``sqrt(4 (th1^2 + th1 th2 + th2^2)) / L0`` over both
    bending components (the secant law is then the gradient of an energy), False: the larger end curvature of the
    cubic element, ``|-(4 th1 + 2 th2)| / L0`` and ``|(2 th1 + 4 th2)| / L0``. Outputs (n_tube,): secant
    ``EI = M(kappa) / kappa`` [N m^2], secant ``GJ = T(phi) / phi`` with the twist per length
    ``phi = |th2_x - th1_x| / L0`` (tube.secant_EI, tube.secant_GJ) and the collapse flag ``kappa > kappa_collapse``;
    with ``energy`` and ``with_tangent`` the material tangent terms ``gb_out``, ``gt_out``
    (tube.secant_material_terms; else 0: ``max_end`` has no consistent tangent, and a stiffness held over a Newton
    solve is a linear law there).
    """
    for k in range(rows.shape[0]):
        e = rows[k]
        L = L0[e]
        if energy:
            s = 0.0
            for j in (1, 2):
                s += th[e, 0, j] * th[e, 0, j] + th[e, 0, j] * th[e, 1, j] + th[e, 1, j] * th[e, 1, j]
            kappa = 2.0 * math.sqrt(s) / L
        else:
            a1, a2 = -(4.0 * th[e, 0, 1] + 2.0 * th[e, 1, 1]) / L, -(4.0 * th[e, 0, 2] + 2.0 * th[e, 1, 2]) / L
            b1, b2 = (2.0 * th[e, 0, 1] + 4.0 * th[e, 1, 1]) / L, (2.0 * th[e, 0, 2] + 4.0 * th[e, 1, 2]) / L
            kappa = max(math.sqrt(a1 * a1 + a2 * a2), math.sqrt(b1 * b1 + b2 * b2))
        x = EI0[k] * kappa / M_max[k]
        EI_out[k] = EI0[k] * ((1.0 - 0.5 * x) if x < 1e-6 else -math.expm1(-x) / x)
        M_c, dM_c = 0.0, 0.0  # fold contact (tube.fold_contact)
        if kappa > kappa_fold[k]:
            a = kappa_closed[k] - kappa_fold[k]
            xf = kappa - kappa_fold[k]
            xe = _FOLD_LINEAR * a
            xi = min(xf, xe)
            u = a - xi
            M_c = M_max[k] * (xi / u) ** 2
            dM_c = M_max[k] * 2.0 * xi * a / (u * u * u)
            M_c += dM_c * max(xf - xe, 0.0)
            EI_out[k] += M_c / kappa
        y = c2[k] * abs(th[e, 1, 0] - th[e, 0, 0]) / L
        GJ_out[k] = GJ0[k] * ((1.0 - y * y / 3.0) if y < 1e-6 else math.atan(y) / y)
        collapsed_out[k] = abs(kappa) > kappa_collapse[k]
        gb_out[k], gt_out[k] = 0.0, 0.0
        if energy and with_tangent:
            if x > _SECANT_TINY:  # (EI_t - EI_s) / EI0 = exp(-x) - (1 - exp(-x)) / x, its series for small x
                dd = (-0.5 * x + x * x / 3.0 - x * x * x / 8.0) if x < 1e-4 else math.exp(-x) + math.expm1(-x) / x
                num = EI0[k] * dd + ((dM_c - M_c / kappa) if M_c > 0.0 else 0.0)
                gb_out[k] = num / (kappa * kappa * L * EI_out[k] * EI_out[k])
            if y > _SECANT_TINY:  # (GJ_t - GJ_s) / GJ0 = 1 / (1 + y^2) - atan(y) / y
                dd = (-2.0 * y * y / 3.0 + 4.0 * y ** 4 / 5.0) if y < 1e-4 else 1.0 / (1.0 + y * y) - math.atan(y) / y
                phi = y / c2[k]
                gt_out[k] = GJ0[k] * dd / (phi * phi * L * GJ_out[k] * GJ_out[k])


@njit(**_JIT)
def rotate_nodes(Rn, dw, out):
    """``out[n] = expm(dw[n]) @ Rn[n]`` (Rodrigues, series below ``_ROT_SMALL`` as :func:`rotations.expm`)."""
    for n in range(Rn.shape[0]):
        w0, w1, w2 = dw[n, 0], dw[n, 1], dw[n, 2]
        t2 = w0 * w0 + w1 * w1 + w2 * w2
        t = math.sqrt(t2)
        if t < _ROT_SMALL:
            a = 1.0 - t2 / 6.0
            b = 0.5 - t2 / 24.0
        else:
            a = math.sin(t) / t
            b = (1.0 - math.cos(t)) / t2
        # E = I + a K + b K K with K = skew(w); K K = w w^T - t2 I
        e00 = 1.0 + b * (w0 * w0 - t2)
        e11 = 1.0 + b * (w1 * w1 - t2)
        e22 = 1.0 + b * (w2 * w2 - t2)
        e01 = -a * w2 + b * w0 * w1
        e10 = a * w2 + b * w0 * w1
        e02 = a * w1 + b * w0 * w2
        e20 = -a * w1 + b * w0 * w2
        e12 = -a * w0 + b * w1 * w2
        e21 = a * w0 + b * w1 * w2
        for j in range(3):
            r0, r1, r2 = Rn[n, 0, j], Rn[n, 1, j], Rn[n, 2, j]
            out[n, 0, j] = e00 * r0 + e01 * r1 + e02 * r2
            out[n, 1, j] = e10 * r0 + e11 * r1 + e12 * r2
            out[n, 2, j] = e20 * r0 + e21 * r1 + e22 * r2


@njit(**_JIT)
def scatter_add(out, index, values):
    """``out[index[i]] += values[i]`` for all i (unbuffered, like ``np.add.at``; ``out`` is not cleared)."""
    for i in range(index.shape[0]):
        out[index[i]] += values[i]


@njit(**_JIT)
def beam_set_bending_torsion(rows, EI, GJ, g_bend, g_twist, L0, EI2, EI3, GJ_out, k11, k12, kmat):
    """``BeamSet.set_bending_torsion`` in one loop (the inflated tubes' secant stiffness, set at every iterate):
    ``EI2 = EI3 = EI``, ``GJ`` and the diagonal local blocks ``k11 = (GJ, 4 EI, 4 EI) / L0``, ``k12 = (-GJ, 2 EI,
    2 EI) / L0`` of the beams ``rows``, and the material terms ``kmat = (g_bend, g_twist)`` (zero-length arrays:
    0). The same operations as the NumPy method, so the same bits."""
    has_b, has_t = g_bend.shape[0] > 0, g_twist.shape[0] > 0
    for i in range(rows.shape[0]):
        r = rows[i]
        ei, gj = EI[i], GJ[i]
        EI2[r] = ei
        EI3[r] = ei
        GJ_out[r] = gj
        iL = 1.0 / L0[r]
        k11[r, 0] = gj * iL
        k11[r, 1] = 4.0 * ei * iL
        k11[r, 2] = 4.0 * ei * iL
        k12[r, 0] = -gj * iL
        k12[r, 1] = 2.0 * ei * iL
        k12[r, 2] = 2.0 * ei * iL
        kmat[r, 0] = g_bend[i] if has_b else 0.0
        kmat[r, 1] = g_twist[i] if has_t else 0.0


@njit(**_JIT)
def csc_gather_matvec(data, entries, indices, indptr, scale, x, out):
    """``out = (scale A) x`` for the CSC matrix ``A`` whose values are ``data[entries]`` (a sub-pattern of a larger
    pattern's data, e.g. its translation-translation entries) with ``indices`` and ``indptr``: scipy's product of
    ``csc_matrix((scale * data[entries], indices, indptr))`` in the same order of operations, without gathering
    the values into a new matrix. ``out`` (length of ``x``) is overwritten."""
    out[:] = 0.0
    for j in range(indptr.shape[0] - 1):
        xj = x[j]
        for k in range(indptr[j], indptr[j + 1]):
            out[indices[k]] += (scale * data[entries[k]]) * xj


@njit(**_JIT)
def beam_internal(x_e, R_e, R0, L0, EA, k11, k12, kmat, f_out, K_out, U_out, want_K=True):
    """Co-rotational Euler-Bernoulli beams, as :meth:`kite_env.structure.beam.BeamSet.internal`.

    Parameters
    ----------
    x_e : (n, 2, 3) float [m]; R_e : (n, 2, 3, 3) float   node positions and nodal rotations.
    R0 : (n, 3, 3) float                                   reference element frames (columns e1, e2, e3).
    L0, EA : (n,) float [m], [N];  k11, k12 : (n, 3) float [N m]   local stiffness diagonals (``BeamSet._k11``).
    kmat : (n, 2) float [1/(N m)]   rank-one material terms of a moment law ``m = k(theta) theta``
                                  (``BeamSet._kmat``): ``dm/dtheta = K_l + g m m^T`` over the bending (column 0) and
                                  the torsion (column 1) components; 0 for a linear element.
    f_out : (n, 12), K_out : (n, 12, 12), U_out : (n,) float   outputs (overwritten).
    want_K : bool   compute the tangent; False: only ``f_out`` and ``U_out`` are written (same values).
    """
    n = x_e.shape[0]
    r1, r2, r3, q, tmp3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    qn, th, m, Mi, gw = np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3))
    Rr, Rb, tmp, A = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    Tinv, dT, TR = np.empty((2, 3, 3)), np.empty((2, 3, 3)), np.empty((2, 3, 3))
    M, AM, Aq, qr1, qr2 = np.empty(3), np.empty(3), np.empty(3), np.empty((2, 3)), np.empty((2, 3))
    g, bu, dgam, dD = np.empty(12), np.zeros(12), np.empty(12), np.empty(12)
    W, RrTW, Y, Zs = np.empty((3, 12)), np.empty((3, 12)), np.empty((3, 12)), np.empty((3, 12))
    Bth, KlB = np.empty((2, 3, 12)), np.empty((2, 3, 12))
    for e in range(n):
        # ---- co-rotated frame (BeamSet._frame)
        for i in range(3):
            tmp3[i] = x_e[e, 1, i] - x_e[e, 0, i]
        l = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        il = 1.0 / l
        for i in range(3):
            r1[i] = tmp3[i] / l
        for k in range(2):
            for i in range(3):
                qn[k, i] = R_e[e, k, i, 0] * R0[e, 0, 1] + R_e[e, k, i, 1] * R0[e, 1, 1] + R_e[e, k, i, 2] * R0[e, 2, 1]
        for i in range(3):
            q[i] = 0.5 * (qn[0, i] + qn[1, i])
        tmp3[0], tmp3[1], tmp3[2] = _cross(r1[0], r1[1], r1[2], q[0], q[1], q[2])
        nn3 = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        for i in range(3):
            r3[i] = tmp3[i] / nn3
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        for k in range(2):
            for i in range(3):  # Rb = Rr^T R_e[e, k] R0[e]
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th[k, 0], th[k, 1], th[k, 2] = _quat_logm(Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2],
                                                     Rb[2, 0], Rb[2, 1], Rb[2, 2])
        # ---- local forces: m_k = K_l theta, M_k = Rr T_k^{-T} m_k
        N = EA[e] / L0[e] * (l - L0[e])
        for a in range(3):
            m[0, a] = k11[e, a] * th[0, a] + k12[e, a] * th[1, a]
            m[1, a] = k12[e, a] * th[0, a] + k11[e, a] * th[1, a]
        for k in range(2):
            # T_k = T_s^{-1}(theta_k), dT_k = d(T_s^{-T} m_k)/d theta_k (rotations.tangent_inv, beam._dTinvT_m)
            eta, cT, detat, dct, cD = _tinv_coeffs(th[k, 0] * th[k, 0] + th[k, 1] * th[k, 1] + th[k, 2] * th[k, 2])
            tm = th[k, 0] * m[k, 0] + th[k, 1] * m[k, 1] + th[k, 2] * m[k, 2]
            tmd = tm * dct
            for i in range(3):
                dm, tt, ct = detat * m[k, i], tmd * th[k, i], cD * th[k, i]
                for j in range(3):
                    Tinv[k, i, j] = cT * (th[k, i] * th[k, j])
                    dT[k, i, j] = dm * th[k, j] + tt * th[k, j] + ct * m[k, j]
                Tinv[k, i, i] += eta
                dT[k, i, i] += cD * tm
            Tinv[k, 0, 1] += 0.5 * th[k, 2]  # - [theta]x / 2
            Tinv[k, 0, 2] -= 0.5 * th[k, 1]
            Tinv[k, 1, 0] -= 0.5 * th[k, 2]
            Tinv[k, 1, 2] += 0.5 * th[k, 0]
            Tinv[k, 2, 0] += 0.5 * th[k, 1]
            Tinv[k, 2, 1] -= 0.5 * th[k, 0]
            dT[k, 0, 1] += 0.5 * m[k, 2]  # + [m]x / 2
            dT[k, 0, 2] -= 0.5 * m[k, 1]
            dT[k, 1, 0] -= 0.5 * m[k, 2]
            dT[k, 1, 2] += 0.5 * m[k, 0]
            dT[k, 2, 0] += 0.5 * m[k, 1]
            dT[k, 2, 1] -= 0.5 * m[k, 0]
            for b in range(3):  # T^{-T} m
                tmp3[b] = Tinv[k, 0, b] * m[k, 0] + Tinv[k, 1, b] * m[k, 1] + Tinv[k, 2, b] * m[k, 2]
            for a in range(3):
                Mi[k, a] = Rr[a, 0] * tmp3[0] + Rr[a, 1] * tmp3[1] + Rr[a, 2] * tmp3[2]
            for a in range(3):  # T_k^{-1} Rr^T
                for c in range(3):
                    TR[k, a, c] = Tinv[k, a, 0] * Rr[c, 0] + Tinv[k, a, 1] * Rr[c, 1] + Tinv[k, a, 2] * Rr[c, 2]
        U_out[e] = 0.5 * EA[e] / L0[e] * (l - L0[e]) ** 2 + 0.5 * (
            m[0, 0] * th[0, 0] + m[0, 1] * th[0, 1] + m[0, 2] * th[0, 2]
            + m[1, 0] * th[1, 0] + m[1, 1] * th[1, 1] + m[1, 2] * th[1, 2])
        # ---- spin of the element frame: dw_r = W dd
        Dd = q[0] * r2[0] + q[1] * r2[1] + q[2] * r2[2]
        iD = 1.0 / Dd
        gam = q[0] * r1[0] + q[1] * r1[1] + q[2] * r1[2]
        sfac = gam / (l * Dd)
        for k in range(2):
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r3[0], r3[1], r3[2])
            for i in range(3):
                gw[k, i] = tmp3[i] / (2.0 * Dd)
        for i in range(3):
            g[i] = sfac * r3[i]
            g[3 + i] = gw[0, i]
            g[6 + i] = -g[i]
            g[9 + i] = gw[1, i]
        for a in range(3):
            for j in range(12):
                W[a, j] = r1[a] * g[j]
        s0, s1, s2 = r1[0] * il, r1[1] * il, r1[2] * il  # W[:, 0:3] -= [r1]x / l, W[:, 6:9] += [r1]x / l
        W[0, 1] += s2
        W[0, 2] -= s1
        W[1, 0] -= s2
        W[1, 2] += s0
        W[2, 0] += s1
        W[2, 1] -= s0
        W[0, 7] -= s2
        W[0, 8] += s1
        W[1, 6] += s2
        W[1, 8] -= s0
        W[2, 6] -= s1
        W[2, 7] += s0
        # ---- internal force f = N bu + sum_k E_k^T M_k, E_k = P_k - W
        for i in range(3):
            bu[i] = -r1[i]
            bu[6 + i] = r1[i]
            M[i] = Mi[0, i] + Mi[1, i]
        for j in range(12):
            f_out[e, j] = N * bu[j] - (W[0, j] * M[0] + W[1, j] * M[1] + W[2, j] * M[2])
        for i in range(3):
            f_out[e, 3 + i] += Mi[0, i]
            f_out[e, 9 + i] += Mi[1, i]
        if not want_K:
            continue
        # ---- d theta_k / dd = T_k^{-1} Rr^T E_k = T_k^{-1} Rr^T (P_k - W)
        for a in range(3):
            ra0, ra1, ra2 = Rr[0, a], Rr[1, a], Rr[2, a]
            for j in range(12):
                RrTW[a, j] = ra0 * W[0, j] + ra1 * W[1, j] + ra2 * W[2, j]
        for k in range(2):
            for a in range(3):
                t0, t1, t2 = Tinv[k, a, 0], Tinv[k, a, 1], Tinv[k, a, 2]
                for j in range(12):
                    Bth[k, a, j] = -(t0 * RrTW[0, j] + t1 * RrTW[1, j] + t2 * RrTW[2, j])
                for c in range(3):
                    Bth[k, a, 6 * k + 3 + c] += TR[k, a, c]
        for a in range(3):  # K_l B (diagonal 3x3 blocks k11, k12)
            a11, a12 = k11[e, a], k12[e, a]
            for j in range(12):
                KlB[0, a, j] = a11 * Bth[0, a, j] + a12 * Bth[1, a, j]
                KlB[1, a, j] = a12 * Bth[0, a, j] + a11 * Bth[1, a, j]
        gb, gt = kmat[e, 0], kmat[e, 1]
        if gb != 0.0 or gt != 0.0:  # (dm/dtheta) B = K_l B + g m (m^T B) per component group
            for j in range(12):
                sb = m[0, 1] * Bth[0, 1, j] + m[0, 2] * Bth[0, 2, j] + m[1, 1] * Bth[1, 1, j] + m[1, 2] * Bth[1, 2, j]
                st = m[0, 0] * Bth[0, 0, j] + m[1, 0] * Bth[1, 0, j]
                for k in range(2):
                    KlB[k, 0, j] += gt * m[k, 0] * st
                    KlB[k, 1, j] += gb * m[k, 1] * sb
                    KlB[k, 2, j] += gb * m[k, 2] * sb
        # ---- Z_k = Rr (T_k^{-T} (K_l B)_k + dT_k B_k) - [M_k]x W;  Zs = Z_0 + Z_1
        for k in range(2):
            for a in range(3):
                t0, t1, t2 = Tinv[k, 0, a], Tinv[k, 1, a], Tinv[k, 2, a]
                d0, d1, d2 = dT[k, a, 0], dT[k, a, 1], dT[k, a, 2]
                for j in range(12):
                    Y[a, j] = (t0 * KlB[k, 0, j] + t1 * KlB[k, 1, j] + t2 * KlB[k, 2, j]) \
                        + (d0 * Bth[k, 0, j] + d1 * Bth[k, 1, j] + d2 * Bth[k, 2, j])
            mx, my, mz = Mi[k, 0], Mi[k, 1], Mi[k, 2]
            row = 3 + 6 * k
            for j in range(12):
                w0, w1, w2 = W[0, j], W[1, j], W[2, j]
                y0, y1, y2 = Y[0, j], Y[1, j], Y[2, j]
                z0 = Rr[0, 0] * y0 + Rr[0, 1] * y1 + Rr[0, 2] * y2 - (-mz * w1 + my * w2)
                z1 = Rr[1, 0] * y0 + Rr[1, 1] * y1 + Rr[1, 2] * y2 - (mz * w0 - mx * w2)
                z2 = Rr[2, 0] * y0 + Rr[2, 1] * y1 + Rr[2, 2] * y2 - (-my * w0 + mx * w1)
                # K = sum_k E_k^T Z_k = sum_k P_k^T Z_k - W^T (Z_0 + Z_1): the P_k^T Z_k rows here
                K_out[e, row, j] = z0
                K_out[e, row + 1, j] = z1
                K_out[e, row + 2, j] = z2
                if k == 0:
                    Zs[0, j], Zs[1, j], Zs[2, j] = z0, z1, z2
                else:
                    Zs[0, j] += z0
                    Zs[1, j] += z1
                    Zs[2, j] += z2
        for i in range(12):
            w0, w1, w2 = W[0, i], W[1, i], W[2, i]
            rot = (i % 6) >= 3
            for j in range(12):
                v = -(w0 * Zs[0, j] + w1 * Zs[1, j] + w2 * Zs[2, j])
                K_out[e, i, j] = K_out[e, i, j] + v if rot else v
        # ---- axial stiffness EA/L0 bu bu^T and axial-force (geometric) term N A (translation blocks only)
        kax = EA[e] / L0[e]
        for a in range(3):
            for b in range(3):
                A[a, b] = ((1.0 if a == b else 0.0) - r1[a] * r1[b]) * il
        for a in range(3):
            for b in range(3):
                v = kax * r1[a] * r1[b] + N * A[a, b]
                K_out[e, a, b] += v
                K_out[e, a, 6 + b] -= v
                K_out[e, 6 + a, b] -= v
                K_out[e, 6 + a, 6 + b] += v
        # ---- variation of W^T M at fixed M: H = [M]x A / l - (M x r1) r1^T / l^2
        tmp3[0], tmp3[1], tmp3[2] = _cross(M[0], M[1], M[2], r1[0], r1[1], r1[2])
        il2 = il * il
        for a in range(3):
            AM[a] = A[a, 0] * M[0] + A[a, 1] * M[1] + A[a, 2] * M[2]
            Aq[a] = A[a, 0] * q[0] + A[a, 1] * q[1] + A[a, 2] * q[2]
        for b in range(3):
            h0 = (-M[2] * A[1, b] + M[1] * A[2, b]) * il - tmp3[0] * r1[b] * il2
            h1 = (M[2] * A[0, b] - M[0] * A[2, b]) * il - tmp3[1] * r1[b] * il2
            h2 = (-M[1] * A[0, b] + M[0] * A[1, b]) * il - tmp3[2] * r1[b] * il2
            K_out[e, 0, b] -= h0
            K_out[e, 1, b] -= h1
            K_out[e, 2, b] -= h2
            K_out[e, 0, 6 + b] += h0
            K_out[e, 1, 6 + b] += h1
            K_out[e, 2, 6 + b] += h2
            K_out[e, 6, b] += h0
            K_out[e, 7, b] += h1
            K_out[e, 8, b] += h2
            K_out[e, 6, 6 + b] -= h0
            K_out[e, 7, 6 + b] -= h1
            K_out[e, 8, 6 + b] -= h2
        for i in range(12):  # - g (AM12)^T, AM12 = [-AM, 0, AM, 0]
            for b in range(3):
                K_out[e, i, b] += g[i] * AM[b]
                K_out[e, i, 6 + b] -= g[i] * AM[b]
        # ---- - alpha dg, alpha = r1 . M, dg = d g / dd (rows [ds, dgw_0, -ds, dgw_1])
        alpha = r1[0] * M[0] + r1[1] * M[1] + r1[2] * M[2]
        for k in range(2):
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r1[0], r1[1], r1[2])
            for i in range(3):
                qr1[k, i] = 0.5 * tmp3[i]
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r2[0], r2[1], r2[2])
            for i in range(3):
                qr2[k, i] = 0.5 * tmp3[i]
        for i in range(3):
            dgam[i], dgam[3 + i], dgam[6 + i], dgam[9 + i] = -Aq[i], qr1[0, i], Aq[i], qr1[1, i]
            gr2 = gam * il * r2[i]
            dD[i], dD[3 + i], dD[6 + i], dD[9 + i] = gr2, qr2[0, i], -gr2, qr2[1, i]
        ilD = il * iD
        # ds = (r3 dgam^T + gam dr3) / (l D) - s bu^T / l - s dD^T / D,  dr3 = -[r3]x W
        for j in range(12):
            w0, w1, w2 = W[0, j], W[1, j], W[2, j]
            dr0 = r3[2] * w1 - r3[1] * w2
            dr1 = r3[0] * w2 - r3[2] * w0
            dr2 = r3[1] * w0 - r3[0] * w1
            cj = bu[j] * il + dD[j] * iD
            ds0 = (r3[0] * dgam[j] + gam * dr0) * ilD - sfac * r3[0] * cj
            ds1 = (r3[1] * dgam[j] + gam * dr1) * ilD - sfac * r3[1] * cj
            ds2 = (r3[2] * dgam[j] + gam * dr2) * ilD - sfac * r3[2] * cj
            K_out[e, 0, j] -= alpha * ds0
            K_out[e, 1, j] -= alpha * ds1
            K_out[e, 2, j] -= alpha * ds2
            K_out[e, 6, j] += alpha * ds0
            K_out[e, 7, j] += alpha * ds1
            K_out[e, 8, j] += alpha * ds2
        # dgw_k = ((qn_k.r3) W - r3 qn_k^T W + [node-k block]) / (2 D) - gw_k dD^T / D
        i2D = 0.5 * iD
        for k in range(2):
            q0, q1, q2 = qn[k, 0], qn[k, 1], qn[k, 2]
            qr3 = q0 * r3[0] + q1 * r3[1] + q2 * r3[2]
            row = 3 + 6 * k
            for j in range(12):
                w0, w1, w2 = W[0, j], W[1, j], W[2, j]
                qW = q0 * w0 + q1 * w1 + q2 * w2
                dDj = dD[j] * iD
                K_out[e, row, j] -= alpha * ((qr3 * w0 - r3[0] * qW) * i2D - gw[k, 0] * dDj)
                K_out[e, row + 1, j] -= alpha * ((qr3 * w1 - r3[1] * qW) * i2D - gw[k, 1] * dDj)
                K_out[e, row + 2, j] -= alpha * ((qr3 * w2 - r3[2] * qW) * i2D - gw[k, 2] * dDj)
            for a in range(3):
                for b in range(3):
                    K_out[e, row + a, 6 * k + 3 + b] -= alpha * ((qn[k, a] * r3[b] - (qr3 if a == b else 0.0)) * i2D)


# ============================================================================================ shell
@njit(**_JIT)
def _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t):
    """Terms of the wrinkled energy at the angle ``t`` (shell_membrane.relaxed_general, ``terms``)."""
    c2, s2 = math.cos(2.0 * t), math.sin(2.0 * t)
    v0, v1, v2 = 0.5 * (1.0 + c2), 0.5 * (1.0 - c2), s2
    t0, t1, t2 = -s2, s2, 2.0 * c2
    a0 = c00 * v0 + c01 * v1 + c02 * v2
    a1 = c01 * v0 + c11 * v1 + c12 * v2
    a2 = c02 * v0 + c12 * v1 + c22 * v2
    b0 = c00 * t0 + c01 * t1 + c02 * t2
    b1 = c01 * t0 + c11 * t1 + c12 * t2
    b2 = c02 * t0 + c12 * t1 + c22 * t2
    s = S0 * v0 + S1 * v1 + S2 * v2
    st = S0 * t0 + S1 * t1 + S2 * t2
    stt = -2.0 * c2 * S0 + 2.0 * c2 * S1 - 4.0 * s2 * S2
    d = v0 * a0 + v1 * a1 + v2 * a2
    dt = 2.0 * (t0 * a0 + t1 * a1 + t2 * a2)
    dtt = 2.0 * ((t0 * b0 + t1 * b1 + t2 * b2) + (-2.0 * c2 * a0 + 2.0 * c2 * a1 - 4.0 * s2 * a2))
    w = -s / d
    wt = -(st * d - s * dt) / (d * d)
    W_t = w * st + 0.5 * w * w * dt
    W_tt = wt * st + w * stt + w * wt * dt + 0.5 * w * w * dtt
    return a0, a1, a2, b0, b1, b2, s, d, w, wt, W_t, W_tt


@njit(**_JIT)
def _wrinkled_general(c00, c01, c02, c11, c12, c22, S0, S1, S2):
    """The wrinkled state of the relaxed law of any plane-stress matrix (shell_membrane.relaxed_general): energy
    change ``w s / 2``, stress ``S + w a`` and the tangent's corrections ``a a^T / d + g g^T / W_tt``, as the angle
    ``t``'s Newton iteration from the most compressive direction of the taut stress ``(S0, S1, S2)``."""
    t = 0.5 * math.atan2(S2, 0.5 * (S0 - S1)) + 0.5 * math.pi
    for _ in range(_WRINKLE_MAX_ITER):
        W_t, W_tt = _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t)[10:]
        if W_tt > 0.0:
            step = -W_t / W_tt
        else:
            step = -_WRINKLE_MAX_STEP if W_t > 0.0 else _WRINKLE_MAX_STEP
        step = min(max(step, -_WRINKLE_MAX_STEP), _WRINKLE_MAX_STEP)
        t += step
        if abs(step) <= _WRINKLE_STEP_TOL:
            break
    a0, a1, a2, b0, b1, b2, s, d, w, wt, W_t, W_tt = _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t)
    g0, g1, g2 = wt * a0 + w * b0, wt * a1 + w * b1, wt * a2 + w * b2
    curv = 1.0 / W_tt if W_tt > 0.0 else 0.0
    return 0.5 * w * s, w * a0, w * a1, w * a2, a0, a1, a2, 1.0 / d, g0, g1, g2, curv


@njit(**_JIT)
def shell_internal(x_e, R_e, R0, G, A0h, Y, nu, C, K_l, eps, wrinkling, bending, f_out, K_out, U_out, want_K=True,
                   vk=False):
    """Flat shell triangles (relaxed SVK membrane + co-rotational DKT + drilling), as ``ShellSet.internal``.

    Parameters
    ----------
    x_e : (n, 3, 3) float [m]; R_e : (n, 3, 3, 3) float   node positions and nodal rotations.
    R0 : (n, 3, 3) float     reference element frames;  G : (n, 3, 2) float [1/m] shape-function gradients.
    A0h : (n,) float [m^3];  Y, nu : (n,) float [Pa], [-];  C : (n, 3, 3) float [Pa] plane-stress matrices.
    K_l : (n, 9, 9) float [N m]   local bending + drilling stiffness;  eps : float  slack fraction.
    wrinkling : int               the membrane law, ``ShellSet.membrane_law``: 0 plain SVK, 1 the isotropic relaxed
                                  law, 2 the relaxed law of any ``C`` (a woven fabric).
    bending : bool                as the ``ShellSet`` option.
    f_out : (n, 18), K_out : (n, 18, 18), U_out : (n,) float   outputs (overwritten).
    want_K : bool   compute the tangent; False: only ``f_out`` and ``U_out`` are written (same values), ``K_out`` is
                    left untouched (for the residual-only assemblies of the modified Newton iteration).
    vk : bool       von Karman membrane kinematics in the reference frames ``R0`` (``shell_membrane``); False:
                    Green-Lagrange.
    """
    n = x_e.shape[0]
    F, S, D = np.empty((3, 2)), np.empty(3), np.empty((3, 3))
    Fb = np.empty((3, 2))
    B, DB, fm, Km = np.empty((3, 9)), np.empty((3, 9)), np.empty(9), np.empty((9, 9))
    av, bv, nv, r1, r2, r3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    M, br1, br2, ar2 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    Rr, Rb, tmp, Ksum = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    th, m, Mi = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    Tinv, Qm, dT = np.empty((3, 3, 3)), np.empty((3, 3, 3)), np.empty((3, 3, 3))
    W, KthR, P = np.empty((3, 9)), np.empty((3, 9)), np.empty((3, 9))
    Kth, KthC, H, X = np.empty((9, 9)), np.empty((9, 3)), np.empty((9, 9)), np.empty((9, 9))
    Hs, V, ft = np.empty((4, 3, 3)), np.empty((12, 3)), np.empty(9)
    for e in range(n):
        # ---- membrane (shell_membrane.membrane_internal): f_m (9,), K_m (9, 9), energy U
        for i in range(3):
            for II in range(2):
                F[i, II] = x_e[e, 0, i] * G[e, 0, II] + x_e[e, 1, i] * G[e, 1, II] + x_e[e, 2, i] * G[e, 2, II]
        if vk:  # von Karman: the gradient's rows in the reference frame [e1, e2, n0] (shell_membrane)
            h00 = R0[e, 0, 0] * F[0, 0] + R0[e, 1, 0] * F[1, 0] + R0[e, 2, 0] * F[2, 0]
            h01 = R0[e, 0, 0] * F[0, 1] + R0[e, 1, 0] * F[1, 1] + R0[e, 2, 0] * F[2, 1]
            h10 = R0[e, 0, 1] * F[0, 0] + R0[e, 1, 1] * F[1, 0] + R0[e, 2, 1] * F[2, 0]
            h11 = R0[e, 0, 1] * F[0, 1] + R0[e, 1, 1] * F[1, 1] + R0[e, 2, 1] * F[2, 1]
            w0 = R0[e, 0, 2] * F[0, 0] + R0[e, 1, 2] * F[1, 0] + R0[e, 2, 2] * F[2, 0]
            w1 = R0[e, 0, 2] * F[0, 1] + R0[e, 1, 2] * F[1, 1] + R0[e, 2, 2] * F[2, 1]
            Ev0, Ev1, Ev2 = h00 - 1.0 + 0.5 * w0 * w0, h11 - 1.0 + 0.5 * w1 * w1, h01 + h10 + w0 * w1
            for i in range(3):
                Fb[i, 0] = R0[e, i, 0] + R0[e, i, 2] * w0
                Fb[i, 1] = R0[e, i, 1] + R0[e, i, 2] * w1
        else:
            c00 = F[0, 0] * F[0, 0] + F[1, 0] * F[1, 0] + F[2, 0] * F[2, 0]
            c11 = F[0, 1] * F[0, 1] + F[1, 1] * F[1, 1] + F[2, 1] * F[2, 1]
            c01 = F[0, 0] * F[0, 1] + F[1, 0] * F[1, 1] + F[2, 0] * F[2, 1]
            Ev0, Ev1, Ev2 = 0.5 * (c00 - 1.0), 0.5 * (c11 - 1.0), c01
            for i in range(3):
                Fb[i, 0] = F[i, 0]
                Fb[i, 1] = F[i, 1]
        # ---- relaxed SVK law (shell_membrane.relaxed_svk)
        Sf0 = C[e, 0, 0] * Ev0 + C[e, 0, 1] * Ev1 + C[e, 0, 2] * Ev2
        Sf1 = C[e, 1, 0] * Ev0 + C[e, 1, 1] * Ev1 + C[e, 1, 2] * Ev2
        Sf2 = C[e, 2, 0] * Ev0 + C[e, 2, 1] * Ev1 + C[e, 2, 2] * Ev2
        Wf = 0.5 * (Sf0 * Ev0 + Sf1 * Ev1 + Sf2 * Ev2)
        if not wrinkling:
            Wd = Wf
            S[0], S[1], S[2] = Sf0, Sf1, Sf2
            for i in range(3):
                for j in range(3):
                    D[i, j] = C[e, i, j]
        elif wrinkling == 2:  # the relaxed law of any C (shell_membrane.relaxed_general)
            hs = 0.5 * (Sf0 - Sf1)
            s_min = 0.5 * (Sf0 + Sf1) - math.sqrt(hs * hs + Sf2 * Sf2)
            taut = s_min > -_TAUT_TOL * 0.5 * (C[e, 0, 0] + C[e, 1, 1])
            E1 = 0.5 * (Ev0 + Ev1) + math.sqrt((0.5 * (Ev0 - Ev1)) ** 2 + (0.5 * Ev2) ** 2)
            wrink = (E1 > 0.0) and not taut
            cT = (1.0 - eps) * (1.0 if taut else 0.0) + eps
            cW = (1.0 - eps) * (1.0 if wrink else 0.0)
            for i in range(3):
                for j in range(3):
                    D[i, j] = (cT + cW) * C[e, i, j]
            Wd = (cT + cW) * Wf
            S[0], S[1], S[2] = (cT + cW) * Sf0, (cT + cW) * Sf1, (cT + cW) * Sf2
            if wrink:
                dW, dS0, dS1, dS2, a0, a1, a2, di, g0, g1, g2, curv = _wrinkled_general(
                    C[e, 0, 0], C[e, 0, 1], C[e, 0, 2], C[e, 1, 1], C[e, 1, 2], C[e, 2, 2], Sf0, Sf1, Sf2)
                Wd += cW * dW
                S[0] += cW * dS0
                S[1] += cW * dS1
                S[2] += cW * dS2
                aw, gw = (a0, a1, a2), (g0, g1, g2)
                for i in range(3):
                    for j in range(3):
                        D[i, j] -= cW * (aw[i] * aw[j] * di + gw[i] * gw[j] * curv)
        else:
            mean = 0.5 * (Ev0 + Ev1)
            hd = 0.5 * (Ev0 - Ev1)
            e12 = 0.5 * Ev2
            rad = math.sqrt(hd**2 + e12**2)
            if rad > 0.0:
                c2, s2 = hd / rad, e12 / rad
            else:
                c2, s2 = 1.0, 0.0
            E1, E2 = mean + rad, mean - rad
            taut = E2 + nu[e] * E1 > -_TAUT_TOL
            wrink = (E1 > 0.0) and not taut
            E1p = E1 if wrink else 0.0
            gap = E1 - E2 if wrink else 1.0
            mw1 = (0.5 * (1.0 + c2), 0.5 * (1.0 - c2), 0.5 * s2)  # m1
            mw12 = (-0.5 * s2, 0.5 * s2, 0.5 * c2)  # m12
            Ye = Y[e]
            YE = Ye * E1p
            cT = (1.0 - eps) * (1.0 if taut else 0.0) + eps
            cW = (1.0 - eps) * (1.0 if wrink else 0.0)
            Wd = cT * Wf + cW * (0.5 * YE * E1p)
            S[0] = cT * Sf0 + cW * (YE * mw1[0])
            S[1] = cT * Sf1 + cW * (YE * mw1[1])
            S[2] = cT * Sf2 + cW * (YE * mw1[2])
            g2 = 2.0 * YE / gap
            for i in range(3):
                for j in range(3):
                    D[i, j] = cT * C[e, i, j] + cW * (Ye * mw1[i] * mw1[j] + g2 * mw12[i] * mw12[j])
        # ---- B = dE_v/dx (3, 9), node-major x (of Fb);  f = A0 h S^T B;  K = A0 h (B^T D B + (G S G^T) (x) I_3)
        for a in range(3):
            for i in range(3):
                B[0, 3 * a + i] = G[e, a, 0] * Fb[i, 0]
                B[1, 3 * a + i] = G[e, a, 1] * Fb[i, 1]
                B[2, 3 * a + i] = G[e, a, 0] * Fb[i, 1] + G[e, a, 1] * Fb[i, 0]
        ah = A0h[e]
        for k in range(9):
            fm[k] = ah * (S[0] * B[0, k] + S[1] * B[1, k] + S[2] * B[2, k])
        U = ah * Wd
        if want_K:  # membrane tangent K_m = A0 h (B^T D B + (G S G^T) (x) I_3)
            for k in range(9):
                for v in range(3):
                    DB[v, k] = D[v, 0] * B[0, k] + D[v, 1] * B[1, k] + D[v, 2] * B[2, k]
            for k in range(9):  # B^T D B (symmetric)
                b0, b1, b2 = B[0, k], B[1, k], B[2, k]
                for ll in range(k, 9):
                    v = b0 * DB[0, ll] + b1 * DB[1, ll] + b2 * DB[2, ll]
                    Km[k, ll] = v
                    Km[ll, k] = v
            for a in range(3):
                for b in range(3):
                    gsg = G[e, a, 0] * (S[0] * G[e, b, 0] + S[2] * G[e, b, 1]) \
                        + G[e, a, 1] * (S[2] * G[e, b, 0] + S[1] * G[e, b, 1])
                    if vk:  # the prestress's geometric stiffness on the out-of-plane motion only
                        for i in range(3):
                            for j in range(3):
                                Km[3 * a + i, 3 * b + j] += gsg * R0[e, i, 2] * R0[e, j, 2]
                    else:
                        for i in range(3):
                            Km[3 * a + i, 3 * b + i] += gsg
            for k in range(9):
                for ll in range(9):
                    Km[k, ll] *= ah
        if not bending:
            for aa in range(3):
                for i in range(3):
                    f_out[e, 6 * aa + i] = fm[3 * aa + i]
                    f_out[e, 6 * aa + 3 + i] = 0.0
            if want_K:
                for i in range(18):
                    for j in range(18):
                        K_out[e, i, j] = 0.0
                for aa in range(3):
                    for bb in range(3):
                        for i in range(3):
                            for j in range(3):
                                K_out[e, 6 * aa + i, 6 * bb + j] = Km[3 * aa + i, 3 * bb + j]
            U_out[e] = U
            continue
        # ---- element frame (shell_bending.element_frame)
        for i in range(3):
            av[i] = x_e[e, 1, i] - x_e[e, 0, i]
            bv[i] = x_e[e, 2, i] - x_e[e, 0, i]
        nv[0], nv[1], nv[2] = _cross(av[0], av[1], av[2], bv[0], bv[1], bv[2])
        lam = av[0] * av[0] + av[1] * av[1] + av[2] * av[2]
        nu2 = nv[0] * nv[0] + nv[1] * nv[1] + nv[2] * nv[2]
        l = math.sqrt(lam)
        nn = math.sqrt(nu2)
        for i in range(3):
            r1[i] = av[i] / l
            r3[i] = nv[i] / nn
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        # ---- local rotations theta_k, moments m = K_l theta, M_k = Rr T_k^{-T} m_k, Qm_k = T_k^{-1} Rr^T
        for k in range(3):
            for i in range(3):  # Rb = Rr^T R_e[e, k] R0[e]
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th[k, 0], th[k, 1], th[k, 2] = _log_rotation(Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2],
                                                     Rb[2, 0], Rb[2, 1], Rb[2, 2])
        Ub = 0.0
        for k in range(3):
            for a in range(3):
                s_ = 0.0
                for l2 in range(3):
                    for b in range(3):
                        s_ += K_l[e, 3 * k + a, 3 * l2 + b] * th[l2, b]
                m[k, a] = s_
                Ub += s_ * th[k, a]
        U_out[e] = U + 0.5 * Ub
        for i in range(3):
            M[i] = 0.0
        for k in range(3):
            # T_k = T_s^{-1}(theta_k), dT_k = d(T_s^{-T} m_k)/d theta_k (rotations.tangent_inv, beam._dTinvT_m)
            eta, cT, detat, dct, cD = _tinv_coeffs(th[k, 0] * th[k, 0] + th[k, 1] * th[k, 1] + th[k, 2] * th[k, 2])
            tm = th[k, 0] * m[k, 0] + th[k, 1] * m[k, 1] + th[k, 2] * m[k, 2]
            tmd = tm * dct
            for i in range(3):
                dm, tt, ct = detat * m[k, i], tmd * th[k, i], cD * th[k, i]
                for j in range(3):
                    Tinv[k, i, j] = cT * (th[k, i] * th[k, j])
                    dT[k, i, j] = dm * th[k, j] + tt * th[k, j] + ct * m[k, j]
                Tinv[k, i, i] += eta
                dT[k, i, i] += cD * tm
            Tinv[k, 0, 1] += 0.5 * th[k, 2]  # - [theta]x / 2
            Tinv[k, 0, 2] -= 0.5 * th[k, 1]
            Tinv[k, 1, 0] -= 0.5 * th[k, 2]
            Tinv[k, 1, 2] += 0.5 * th[k, 0]
            Tinv[k, 2, 0] += 0.5 * th[k, 1]
            Tinv[k, 2, 1] -= 0.5 * th[k, 0]
            dT[k, 0, 1] += 0.5 * m[k, 2]  # + [m]x / 2
            dT[k, 0, 2] -= 0.5 * m[k, 1]
            dT[k, 1, 0] -= 0.5 * m[k, 2]
            dT[k, 1, 2] += 0.5 * m[k, 0]
            dT[k, 2, 0] += 0.5 * m[k, 1]
            dT[k, 2, 1] -= 0.5 * m[k, 0]
            for b in range(3):
                tmp[0, b] = Tinv[k, 0, b] * m[k, 0] + Tinv[k, 1, b] * m[k, 1] + Tinv[k, 2, b] * m[k, 2]
            for a in range(3):
                Mi[k, a] = Rr[a, 0] * tmp[0, 0] + Rr[a, 1] * tmp[0, 1] + Rr[a, 2] * tmp[0, 2]
                M[a] += Mi[k, a]
            for a in range(3):
                for c in range(3):
                    Qm[k, a, c] = Tinv[k, a, 0] * Rr[c, 0] + Tinv[k, a, 1] * Rr[c, 1] + Tinv[k, a, 2] * Rr[c, 2]
        # ---- frame spin W (shell_bending.frame_spin)
        inn = 1.0 / nn
        il = 1.0 / l
        br2[0], br2[1], br2[2] = _cross(bv[0], bv[1], bv[2], r2[0], r2[1], r2[2])
        br1[0], br1[1], br1[2] = _cross(bv[0], bv[1], bv[2], r1[0], r1[1], r1[2])
        ar2[0], ar2[1], ar2[2] = _cross(av[0], av[1], av[2], r2[0], r2[1], r2[2])
        for i in range(3):
            for j in range(3):
                wa = (-r1[i] * br2[j] + r2[i] * br1[j]) * inn + r3[i] * r2[j] * il
                wb = r1[i] * ar2[j] * inn
                W[i, j] = -wa - wb
                W[i, 3 + j] = wa
                W[i, 6 + j] = wb
        for j in range(9):
            ft[j] = -(W[0, j] * M[0] + W[1, j] * M[1] + W[2, j] * M[2])
        if not want_K:
            for aa in range(3):
                for i in range(3):
                    f_out[e, 6 * aa + i] = fm[3 * aa + i] + ft[3 * aa + i]
                    f_out[e, 6 * aa + 3 + i] = Mi[aa, i]
            continue
        # ---- K_th = Q^T K_l Q + blockdiag(Rr dT_k Qm_k),  Q = blockdiag(Qm_k); X = K_l Q first
        for l2 in range(3):
            for j in range(3):
                u0, u1, u2 = Qm[l2, 0, j], Qm[l2, 1, j], Qm[l2, 2, j]
                for r in range(9):
                    X[r, 3 * l2 + j] = K_l[e, r, 3 * l2] * u0 + K_l[e, r, 3 * l2 + 1] * u1 + K_l[e, r, 3 * l2 + 2] * u2
        for k in range(3):
            q00, q01, q02 = Qm[k, 0, 0], Qm[k, 0, 1], Qm[k, 0, 2]
            q10, q11, q12 = Qm[k, 1, 0], Qm[k, 1, 1], Qm[k, 1, 2]
            q20, q21, q22 = Qm[k, 2, 0], Qm[k, 2, 1], Qm[k, 2, 2]
            for c in range(9):
                x0, x1, x2 = X[3 * k, c], X[3 * k + 1, c], X[3 * k + 2, c]
                Kth[3 * k, c] = q00 * x0 + q10 * x1 + q20 * x2
                Kth[3 * k + 1, c] = q01 * x0 + q11 * x1 + q21 * x2
                Kth[3 * k + 2, c] = q02 * x0 + q12 * x1 + q22 * x2
            for i in range(3):  # + (Rr dT_k) Qm_k
                g0 = Rr[i, 0] * dT[k, 0, 0] + Rr[i, 1] * dT[k, 1, 0] + Rr[i, 2] * dT[k, 2, 0]
                g1 = Rr[i, 0] * dT[k, 0, 1] + Rr[i, 1] * dT[k, 1, 1] + Rr[i, 2] * dT[k, 2, 1]
                g2 = Rr[i, 0] * dT[k, 0, 2] + Rr[i, 1] * dT[k, 1, 2] + Rr[i, 2] * dT[k, 2, 2]
                Kth[3 * k + i, 3 * k] += g0 * q00 + g1 * q10 + g2 * q20
                Kth[3 * k + i, 3 * k + 1] += g0 * q01 + g1 * q11 + g2 * q21
                Kth[3 * k + i, 3 * k + 2] += g0 * q02 + g1 * q12 + g2 * q22
        # ---- column / row sums: K_th W_st = KthC W, W_st^T K_th = W^T KthR, Ksum = sum of all 3x3 blocks
        for r in range(9):
            for j in range(3):
                KthC[r, j] = Kth[r, j] + Kth[r, 3 + j] + Kth[r, 6 + j]
        for i in range(3):
            for c in range(9):
                KthR[i, c] = Kth[i, c] + Kth[3 + i, c] + Kth[6 + i, c]
            for j in range(3):
                Ksum[i, j] = KthC[i, j] + KthC[3 + i, j] + KthC[6 + i, j]
        Ksum[0, 1] -= M[2]  # + [M]x
        Ksum[0, 2] += M[1]
        Ksum[1, 0] += M[2]
        Ksum[1, 2] -= M[0]
        Ksum[2, 0] -= M[1]
        Ksum[2, 1] += M[0]
        # ---- H = d(W^T M)/dx at fixed M (shell_bending.frame_spin_hessian), (a, b) blocks first
        a0, a1, a2 = av[0], av[1], av[2]
        b0, b1, b2 = bv[0], bv[1], bv[2]
        n0, n1, n2 = nv[0], nv[1], nv[2]
        M0, M1, M2 = M[0], M[1], M[2]
        p0, p1, p2 = _cross(n0, n1, n2, M0, M1, M2)
        s = n0 * M0 + n1 * M1 + n2 * M2
        Ma = M0 * a0 + M1 * a1 + M2 * a2
        Mb = M0 * b0 + M1 * b1 + M2 * b2
        ab = a0 * b0 + a1 * b1 + a2 * b2
        inu = 1.0 / nu2
        inl = 1.0 / (nu2 * lam)
        inu2 = inu**2
        # rows of V: 0 dnu_a = 2 b x n, 1 dnu_b = 2 n x a, 2 q = n x a, 3 bp, 4 ap, 5 Va, 6 Vb, 8-11 skew vectors
        x0, x1, x2 = _cross(b0, b1, b2, n0, n1, n2)
        V[0, 0], V[0, 1], V[0, 2] = 2.0 * x0, 2.0 * x1, 2.0 * x2
        x0, x1, x2 = _cross(n0, n1, n2, a0, a1, a2)
        V[1, 0], V[1, 1], V[1, 2] = 2.0 * x0, 2.0 * x1, 2.0 * x2
        V[2, 0], V[2, 1], V[2, 2] = x0, x1, x2
        x0, x1, x2 = _cross(b0, b1, b2, p0, p1, p2)
        V[3, 0], V[3, 1], V[3, 2] = x0 * inu2, x1 * inu2, x2 * inu2
        x0, x1, x2 = _cross(a0, a1, a2, p0, p1, p2)
        V[4, 0], V[4, 1], V[4, 2] = x0 * inu2, x1 * inu2, x2 * inu2
        x0, x1, x2 = _cross(b0, b1, b2, M0, M1, M2)
        y0, y1, y2 = _cross(M0, M1, M2, a0, a1, a2)
        V[5, 0] = x0 - s * (V[0, 0] * inu + 2.0 * a0 / lam)
        V[5, 1] = x1 - s * (V[0, 1] * inu + 2.0 * a1 / lam)
        V[5, 2] = x2 - s * (V[0, 2] * inu + 2.0 * a2 / lam)
        V[6, 0] = y0 - (s * inu) * V[1, 0]
        V[6, 1] = y1 - (s * inu) * V[1, 1]
        V[6, 2] = y2 - (s * inu) * V[1, 2]
        # skew-symmetric and diagonal parts of the (a, b) blocks
        V[8, 0], V[8, 1], V[8, 2] = (Mb * inu) * b0 + (s * inl) * n0, (Mb * inu) * b1 + (s * inl) * n1, \
            (Mb * inu) * b2 + (s * inl) * n2
        V[9, 0], V[9, 1], V[9, 2] = (p0 - Ma * b0) * inu, (p1 - Ma * b1) * inu, (p2 - Ma * b2) * inu
        V[10, 0], V[10, 1], V[10, 2] = (-p0 - Mb * a0) * inu, (-p1 - Mb * a1) * inu, (-p2 - Mb * a2) * inu
        V[11, 0], V[11, 1], V[11, 2] = (Ma * inu) * a0, (Ma * inu) * a1, (Ma * inu) * a2
        for blk in range(4):
            r = 8 + blk
            Hs[blk, 0, 0], Hs[blk, 0, 1], Hs[blk, 0, 2] = 0.0, -V[r, 2], V[r, 1]
            Hs[blk, 1, 0], Hs[blk, 1, 1], Hs[blk, 1, 2] = V[r, 2], 0.0, -V[r, 0]
            Hs[blk, 2, 0], Hs[blk, 2, 1], Hs[blk, 2, 2] = -V[r, 1], V[r, 0], 0.0
        for k in range(3):
            Hs[0, k, k] -= s * ab * inl
            Hs[1, k, k] += s * inu
        # rank-one parts
        for i in range(3):
            qs = V[2, i] * inl
            sb = (s * inl) * bv[i]
            sa = (s * inl) * av[i]
            nM = nv[i] * inu
            bp = V[3, i]
            ap = V[4, i]
            for j in range(3):
                Hs[0, i, j] += bp * V[0, j] + qs * V[5, j] + sb * av[j]
                Hs[1, i, j] += bp * V[1, j] + qs * V[6, j] - nM * M[j] - sa * av[j]
                Hs[2, i, j] += -ap * V[0, j] + nM * M[j]
                Hs[3, i, j] += -ap * V[1, j]
        # chain rule to node-major x: a = x1 - x0, b = x2 - x0
        for i in range(3):
            for j in range(3):
                haa, hab, hba, hbb = Hs[0, i, j], Hs[1, i, j], Hs[2, i, j], Hs[3, i, j]
                ha_, hb_ = haa + hba, hab + hbb
                H[i, j] = ha_ + hb_
                H[i, 3 + j] = -ha_
                H[i, 6 + j] = -hb_
                H[3 + i, j] = -(haa + hab)
                H[3 + i, 3 + j] = haa
                H[3 + i, 6 + j] = hab
                H[6 + i, j] = -(hba + hbb)
                H[6 + i, 3 + j] = hba
                H[6 + i, 6 + j] = hbb
        for i in range(3):  # P = (Ksum + [M]x) W
            for c in range(9):
                P[i, c] = Ksum[i, 0] * W[0, c] + Ksum[i, 1] * W[1, c] + Ksum[i, 2] * W[2, c]
        # ---- scatter into the 18x18 node-major [u, w] layout:
        #      K_tt = W^T P - H + K_m,  K_tr = -W^T KthR,  K_rt = -(KthC + [M_k]x) W,  K_rr = K_th
        for aa in range(3):
            for i in range(3):
                ra, rr = 6 * aa, 6 * aa + 3
                r9 = 3 * aa + i
                f_out[e, ra + i] = fm[r9] + ft[r9]
                f_out[e, rr + i] = Mi[aa, i]
                if i == 0:
                    s0, s1, s2 = 0.0, -Mi[aa, 2], Mi[aa, 1]
                elif i == 1:
                    s0, s1, s2 = Mi[aa, 2], 0.0, -Mi[aa, 0]
                else:
                    s0, s1, s2 = -Mi[aa, 1], Mi[aa, 0], 0.0
                c0, c1, c2 = KthC[r9, 0] + s0, KthC[r9, 1] + s1, KthC[r9, 2] + s2
                w0, w1, w2 = W[0, r9], W[1, r9], W[2, r9]
                for bb in range(3):
                    for j in range(3):
                        c9 = 3 * bb + j
                        K_out[e, ra + i, 6 * bb + j] = (w0 * P[0, c9] + w1 * P[1, c9] + w2 * P[2, c9]) \
                            - H[r9, c9] + Km[r9, c9]
                        K_out[e, ra + i, 6 * bb + 3 + j] = -(w0 * KthR[0, c9] + w1 * KthR[1, c9] + w2 * KthR[2, c9])
                        K_out[e, rr + i, 6 * bb + j] = -(c0 * W[0, c9] + c1 * W[1, c9] + c2 * W[2, c9])
                        K_out[e, rr + i, 6 * bb + 3 + j] = Kth[r9, c9]


# ============================================================================================ hem rods
@njit(**_JIT)
def _mm3(A, B, out):
    """``out = A @ B`` for 3 x 3 arrays (``out`` distinct from both)."""
    for p in range(3):
        for q in range(3):
            out[p, q] = A[p, 0] * B[0, q] + A[p, 1] * B[1, q] + A[p, 2] * B[2, q]


@njit(**_JIT)
def hem_internal(x_e, R_e, e1, e2, L0, EA, EI, GJ, f_out, K_out, want_K=True):
    """Frame-free hem rods, as :meth:`kite_env.structure.hem.HemSet.internal` (the NumPy reference, whose docstring
    and module docstring derive the energy, force and tangent; the same terms here, element by element).

    Parameters
    ----------
    x_e : (n, 2, 3) float [m]; R_e : (n, 2, 3, 3) float   node positions and nodal rotations.
    e1, e2 : (n, 3) float            the undeformed axis and up vector (the directors ``a_i = R_i e1``, ``b_i = R_i
                                     e2``).
    L0, EA, EI, GJ : (n,) float      [m], [N], [N m^2], [N m^2].
    f_out : (n, 12) float            internal forces ``[u1, w1, u2, w2]`` (written).
    K_out : (n, 12, 12) float        tangents (written when ``want_K``; else may be (1, 12, 12)).
    """
    n = x_e.shape[0]
    D = np.empty((4, 3))  # the directors a1, b1, a2, b2 (index 2 i + (0: a, 1: b) for node i)
    g = np.empty((4, 3))  # the energy's gradient in each director
    r = np.empty(3)
    gr = np.empty(3)
    sr = np.empty(3)  # d s / d r = b1 x b2
    sb = np.empty((4, 3))  # d s / d b1, d s / d b2 at rows 1, 3
    Hrr = np.empty((3, 3))
    Hr = np.empty((4, 3, 3))  # H(r, u)
    Huv = np.zeros((4, 4, 3, 3))
    S = np.empty((4, 3, 3))  # skew(u)
    P = np.empty((3, 3))
    T1 = np.empty((3, 3))
    T2 = np.empty((3, 3))
    Acc = np.empty((3, 3))
    Acc2 = np.empty((3, 3))
    for e in range(n):
        d0 = x_e[e, 1, 0] - x_e[e, 0, 0]
        d1 = x_e[e, 1, 1] - x_e[e, 0, 1]
        d2 = x_e[e, 1, 2] - x_e[e, 0, 2]
        l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        il = 1.0 / l
        r[0], r[1], r[2] = d0 * il, d1 * il, d2 * il
        for i in range(2):
            for p in range(3):
                D[2 * i, p] = R_e[e, i, p, 0] * e1[e, 0] + R_e[e, i, p, 1] * e1[e, 1] + R_e[e, i, p, 2] * e1[e, 2]
                D[2 * i + 1, p] = (R_e[e, i, p, 0] * e2[e, 0] + R_e[e, i, p, 1] * e2[e, 1]
                                   + R_e[e, i, p, 2] * e2[e, 2])
        c1 = r[0] * D[0, 0] + r[1] * D[0, 1] + r[2] * D[0, 2]
        c2 = r[0] * D[2, 0] + r[1] * D[2, 1] + r[2] * D[2, 2]
        # s = r . (b1 x b2) and its gradients: s_r = b1 x b2, s_b1 = b2 x r, s_b2 = r x b1
        sr[0], sr[1], sr[2] = _cross(D[1, 0], D[1, 1], D[1, 2], D[3, 0], D[3, 1], D[3, 2])
        sb[1, 0], sb[1, 1], sb[1, 2] = _cross(D[3, 0], D[3, 1], D[3, 2], r[0], r[1], r[2])
        sb[3, 0], sb[3, 1], sb[3, 2] = _cross(r[0], r[1], r[2], D[1, 0], D[1, 1], D[1, 2])
        s = r[0] * sr[0] + r[1] * sr[1] + r[2] * sr[2]
        cb = D[1, 0] * D[3, 0] + D[1, 1] * D[3, 1] + D[1, 2] * D[3, 2]
        k = EI[e] / L0[e]
        G = GJ[e] / L0[e]
        N = EA[e] * (l - L0[e]) / L0[e]
        Gs = G * s
        Goc = G * (1.0 - cb)
        f2, f1 = 4.0 + 2.0 * c2, 4.0 + 2.0 * c1
        for p in range(3):
            gr[p] = k * (-f2 * D[0, p] - f1 * D[2, p]) + Gs * sr[p]
            g[0, p] = k * (2.0 * D[2, p] - f2 * r[p])
            g[2, p] = k * (2.0 * D[0, p] - f1 * r[p])
            g[1, p] = Gs * sb[1, p] - Goc * D[3, p]
            g[3, p] = Gs * sb[3, p] - Goc * D[1, p]
        rg = r[0] * gr[0] + r[1] * gr[1] + r[2] * gr[2]
        for p in range(3):
            fd = N * r[p] + (gr[p] - rg * r[p]) * il
            f_out[e, p] = -fd
            f_out[e, 6 + p] = fd
        for i in range(2):
            m0, m1, m2 = _cross(D[2 * i, 0], D[2 * i, 1], D[2 * i, 2], g[2 * i, 0], g[2 * i, 1], g[2 * i, 2])
            n0, n1, n2 = _cross(D[2 * i + 1, 0], D[2 * i + 1, 1], D[2 * i + 1, 2],
                                g[2 * i + 1, 0], g[2 * i + 1, 1], g[2 * i + 1, 2])
            f_out[e, 6 * i + 3] = m0 + n0
            f_out[e, 6 * i + 4] = m1 + n1
            f_out[e, 6 * i + 5] = m2 + n2
        if not want_K:
            continue
        # the energy's second derivatives (the reference's dictionary H; absent pairs are zero)
        for p in range(3):
            for q in range(3):
                dl = 1.0 if p == q else 0.0
                P[p, q] = dl - r[p] * r[q]
                Hrr[p, q] = -2.0 * k * (D[0, p] * D[2, q] + D[2, p] * D[0, q]) + G * sr[p] * sr[q]
                Hr[0, p, q] = k * (-f2 * dl - 2.0 * D[2, p] * r[q])
                Hr[2, p, q] = k * (-f1 * dl - 2.0 * D[0, p] * r[q])
                Hr[1, p, q] = G * sr[p] * sb[1, q]
                Hr[3, p, q] = G * sr[p] * sb[3, q]
                Huv[1, 1, p, q] = G * (sb[1, p] * sb[1, q] + D[3, p] * D[3, q])
                Huv[3, 3, p, q] = G * (sb[3, p] * sb[3, q] + D[1, p] * D[1, q])
                Huv[1, 3, p, q] = G * (sb[1, p] * sb[3, q] + D[3, p] * D[1, q]) - Goc * dl
        # the skew parts: H(r, b1) -= Gs [b2]x, H(r, b2) += Gs [b1]x, H(b1, b2) -= Gs [r]x
        for u in range(4):
            S[u, 0, 0], S[u, 0, 1], S[u, 0, 2] = 0.0, -D[u, 2], D[u, 1]
            S[u, 1, 0], S[u, 1, 1], S[u, 1, 2] = D[u, 2], 0.0, -D[u, 0]
            S[u, 2, 0], S[u, 2, 1], S[u, 2, 2] = -D[u, 1], D[u, 0], 0.0
        for p in range(3):
            for q in range(3):
                Hr[1, p, q] -= Gs * S[3, p, q]
                Hr[3, p, q] += Gs * S[1, p, q]
        Huv[1, 3, 0, 1] += Gs * r[2]
        Huv[1, 3, 0, 2] -= Gs * r[1]
        Huv[1, 3, 1, 0] -= Gs * r[2]
        Huv[1, 3, 1, 2] += Gs * r[0]
        Huv[1, 3, 2, 0] += Gs * r[1]
        Huv[1, 3, 2, 1] -= Gs * r[0]
        for p in range(3):
            for q in range(3):
                Huv[0, 2, p, q] = 2.0 * k * P[p, q]
                Huv[2, 0, p, q] = 2.0 * k * P[q, p]
                Huv[3, 1, p, q] = Huv[1, 3, q, p]
        # K_dd = EA/L0 r r^T + N/l P - (rg P + r Pg^T + Pg r^T) / l^2 + P Hrr P / l^2
        _mm3(P, Hrr, T1)
        _mm3(T1, P, T2)
        il2 = il * il
        for p in range(3):
            pgp = gr[p] - rg * r[p]
            for q in range(3):
                pgq = gr[q] - rg * r[q]
                v = (EA[e] / L0[e] * r[p] * r[q] + N * il * P[p, q]
                     - il2 * (rg * P[p, q] + r[p] * pgq + pgp * r[q]) + il2 * T2[p, q])
                K_out[e, p, q] = v
                K_out[e, 6 + p, 6 + q] = v
                K_out[e, p, 6 + q] = -v
                K_out[e, 6 + p, q] = -v
        for i in range(2):
            # K_dw = -P (sum_u H(r, u) S_u) / l;  K_wd = (sum_u S_u H(r, u)^T) P / l
            for p in range(3):
                for q in range(3):
                    Acc[p, q] = 0.0
                    Acc2[p, q] = 0.0
            for u in range(2 * i, 2 * i + 2):
                for p in range(3):
                    for q in range(3):
                        Acc[p, q] += Hr[u, p, 0] * S[u, 0, q] + Hr[u, p, 1] * S[u, 1, q] + Hr[u, p, 2] * S[u, 2, q]
                        Acc2[p, q] += S[u, p, 0] * Hr[u, q, 0] + S[u, p, 1] * Hr[u, q, 1] + S[u, p, 2] * Hr[u, q, 2]
            _mm3(P, Acc, T1)
            _mm3(Acc2, P, T2)
            for p in range(3):
                for q in range(3):
                    kdw = -il * T1[p, q]
                    kwd = il * T2[p, q]
                    K_out[e, p, 6 * i + 3 + q] = -kdw
                    K_out[e, 6 + p, 6 * i + 3 + q] = kdw
                    K_out[e, 6 * i + 3 + p, q] = -kwd
                    K_out[e, 6 * i + 3 + p, 6 + q] = kwd
            for j in range(2):
                # K_ww = [j == i] sum_u [g_u]x S_u - sum_{u, v} S_u H(u, v) S_v
                for p in range(3):
                    for q in range(3):
                        Acc[p, q] = 0.0
                if j == i:
                    for u in range(2 * i, 2 * i + 2):
                        gu0, gu1, gu2 = g[u, 0], g[u, 1], g[u, 2]
                        for q in range(3):
                            Acc[0, q] += -gu2 * S[u, 1, q] + gu1 * S[u, 2, q]
                            Acc[1, q] += gu2 * S[u, 0, q] - gu0 * S[u, 2, q]
                            Acc[2, q] += -gu1 * S[u, 0, q] + gu0 * S[u, 1, q]
                for u in range(2 * i, 2 * i + 2):
                    for v in range(2 * j, 2 * j + 2):
                        if (u == 0 or u == 2) and u == v:
                            continue  # H(a_i, a_i) = 0
                        if (u % 2) != (v % 2):
                            continue  # H(a, b) = 0
                        for p in range(3):
                            for q in range(3):
                                T1[p, q] = (S[u, p, 0] * Huv[u, v, 0, q] + S[u, p, 1] * Huv[u, v, 1, q]
                                            + S[u, p, 2] * Huv[u, v, 2, q])
                        for p in range(3):
                            for q in range(3):
                                Acc[p, q] -= T1[p, 0] * S[v, 0, q] + T1[p, 1] * S[v, 1, q] + T1[p, 2] * S[v, 2, q]
                for p in range(3):
                    for q in range(3):
                        K_out[e, 6 * i + 3 + p, 6 * j + 3 + q] = Acc[p, q]
