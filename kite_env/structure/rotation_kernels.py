"""Compiled (numba) rotation helpers shared by the element kernels, and the rotation kernels over all nodes.

The scalar helpers take and return scalars (tuples; the implementation rule of :mod:`kite_env.compiled`):
:func:`_cross`, :func:`_quat_logm` (``rotations.logm`` of one matrix), :func:`_log_rotation`
(``shell_bending._log_rotation``) and :func:`_tinv_coeffs` (the coefficients of ``rotations.tangent_inv`` and of
``beam._dTinvT_m``), with the series and branch thresholds of the reference functions; the element kernels of
:mod:`.beam_kernels`, :mod:`.shell_kernels` and :mod:`.hem_kernels` call them.  The kernels over all nodes:
:func:`relative_rotation_vectors` (the wing's rotations over a time step, :mod:`kite_env.dynamics.wing_dynamics`)
and :func:`rotate_nodes` (the solver's rotation update ``expm(dw) R``).

numba's cache of a kernel in another file does not see a change of this file (:mod:`kite_env.compiled`,
"Compilation and cost"): after editing a helper here, clear ``__pycache__``; ``tests/structure/test_kernels.py``
checks the element kernels against their NumPy references.
"""

from __future__ import annotations

import math

from kite_env.compiled import JIT, njit

# Thresholds of the reference implementations.  Literals, not imports: numba's cache is keyed on this file only,
# so a changed import would not recompile; tests/structure/test_kernels.py checks that they stay equal.
_ROT_SMALL = 1e-6  # rotations.logm: series of the angle/sin factor
_TINV_SMALL = 1e-4  # rotations.tangent_inv: series of eta and c
_TSMALL = 0.2  # beam._tinv_derivative_coeffs: series of eta'/t and c'/t
_LOGROT_SMALL = 1e-4  # shell_bending._log_rotation: series of atan2(s, c)/s
_LOGROT_FAR = 1e-3  # shell_bending._log_rotation: cos(t) below this -> quaternion logm


# Implementation note: the element loops never take array views (``a[e]``, ``a[k]``) and never pass views to
# helpers; each view costs two atomic reference-count updates in numba, which were measured to dominate the
# run time.  Helpers therefore take whole arrays plus indices, or scalars, and return tuples.
@njit(**JIT)
def _cross(u0, u1, u2, v0, v1, v2):
    """Cross product of two 3-vectors given by components; returns a tuple."""
    return u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0


@njit(**JIT)
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


@njit(**JIT)
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


@njit(**JIT)
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


@njit(**JIT)
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


@njit(**JIT)
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
