"""Finite rotations: the one place where rotation vectors and rotation matrices meet.

Conventions (used by every element and by the solver)
------------------------------------------------------
* A nodal orientation is a proper rotation matrix ``R`` (3x3) that maps the node's reference
  triad to its current triad (``R = I`` in the unloaded design state).
* A rotational degree-of-freedom increment is a *spatial* (left) spin ``dtheta`` [rad] expressed in
  the global frame of the analysis: ``R_new = expm(dtheta) @ R_old``.
* ``expm`` is Rodrigues' formula, ``logm`` its inverse with ``|theta| <= pi``.

All functions are vectorised over leading axes: ``theta`` is ``(..., 3)``, ``R`` is ``(..., 3, 3)``.
"""

from __future__ import annotations

import numpy as np

_SMALL = 1e-6


def skew(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix ``[v]x`` with ``skew(v) @ w == cross(v, w)``; ``(..., 3) -> (..., 3, 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def unskew(W: np.ndarray) -> np.ndarray:
    """Axial vector of the skew-symmetric part of ``W``; ``(..., 3, 3) -> (..., 3)``."""
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]], axis=-1
    )


def _coeffs(theta: np.ndarray):
    """Return |theta|, sin(t)/t, (1-cos t)/t^2 with series expansions near zero."""
    t2 = np.einsum("...i,...i->...", theta, theta)
    t = np.sqrt(t2)
    small = t < _SMALL
    ts = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(ts)) / ts**2)
    return t, a, b


def expm(theta: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``theta`` [rad] (Rodrigues); ``(..., 3) -> (..., 3, 3)``."""
    theta = np.asarray(theta, dtype=float)
    _, a, b = _coeffs(theta)
    K = skew(theta)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + a[..., None, None] * K + b[..., None, None] * (K @ K)


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of rotation matrices (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    shape = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    cand = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((R.shape[0], 4))
    # case w largest
    s = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2.0
    q0 = np.stack([0.25 * s, (R[:, 2, 1] - R[:, 1, 2]) / s,
                   (R[:, 0, 2] - R[:, 2, 0]) / s, (R[:, 1, 0] - R[:, 0, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 + R[:, 0, 0] - R[:, 1, 1] - R[:, 2, 2], 1e-300)) * 2.0
    q1 = np.stack([(R[:, 2, 1] - R[:, 1, 2]) / s, 0.25 * s,
                   (R[:, 0, 1] + R[:, 1, 0]) / s, (R[:, 0, 2] + R[:, 2, 0]) / s], -1)
    s = np.sqrt(np.maximum(1.0 - R[:, 0, 0] + R[:, 1, 1] - R[:, 2, 2], 1e-300)) * 2.0
    q2 = np.stack([(R[:, 0, 2] - R[:, 2, 0]) / s, (R[:, 0, 1] + R[:, 1, 0]) / s,
                   0.25 * s, (R[:, 1, 2] + R[:, 2, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 - R[:, 0, 0] - R[:, 1, 1] + R[:, 2, 2], 1e-300)) * 2.0
    q3 = np.stack([(R[:, 1, 0] - R[:, 0, 1]) / s, (R[:, 0, 2] + R[:, 2, 0]) / s,
                   (R[:, 1, 2] + R[:, 2, 1]) / s, 0.25 * s], -1)
    allq = np.stack([q0, q1, q2, q3], axis=1)
    q = allq[np.arange(R.shape[0]), k]
    q *= np.where(q[:, :1] < 0.0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(shape + (4,))


def logm(R: np.ndarray) -> np.ndarray:
    """Rotation vector ``theta`` with ``expm(theta) == R`` and ``|theta| <= pi``; ``(..., 3, 3) -> (..., 3)``."""
    q = quat_from_matrix(R)
    w = q[..., 0]
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    ang = 2.0 * np.arctan2(s, w)
    small = s < _SMALL
    fac = np.where(small, 2.0 / np.maximum(w, 1e-300) * (1.0 - s**2 / (3.0 * np.maximum(w, 1e-300) ** 2)),
                   ang / np.where(small, 1.0, s))
    return fac[..., None] * v


def tangent_inv(theta: np.ndarray) -> np.ndarray:
    """``T_s^{-1}(theta)``: maps a spatial spin variation ``dw`` to the variation of the rotation vector.

    ``d theta = T_s^{-1}(theta) @ dw`` where ``expm(theta + d theta) = expm(dw) @ expm(theta)`` to first
    order (Battini & Pacoste 2002, eq. 13; Crisfield 1997, Vol. 2, Sect. 16.11)::

        T_s^{-1} = eta I + (1 - eta) e e^T - 1/2 [theta]x,   eta = (t/2) / tan(t/2),  e = theta / t
    """
    theta = np.asarray(theta, dtype=float)
    t2 = np.einsum("...i,...i->...", theta, theta)
    t = np.sqrt(t2)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    eta = np.where(small, 1.0 - t2 / 12.0, (ts / 2.0) / np.tan(ts / 2.0))
    # (1 - eta) e e^T = (1 - eta)/t^2 theta theta^T ; (1-eta)/t^2 -> 1/12 for t -> 0
    c = np.where(small, 1.0 / 12.0 + t2 / 720.0, (1.0 - eta) / ts**2)
    eye = np.broadcast_to(np.eye(3), theta.shape[:-1] + (3, 3))
    return (eta[..., None, None] * eye + c[..., None, None] * (theta[..., :, None] * theta[..., None, :])
            - 0.5 * skew(theta))
