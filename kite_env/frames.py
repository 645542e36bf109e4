"""The reference frames of the model (Bosch et al., Sect. II; defined here and nowhere else).

* Wind frame W: inertial; origin at the tether's ground attachment, ``x_w`` along the wind velocity ``v_w``,
  ``z_w`` up (perpendicular to the ground), ``y_w = z_w × x_w``.
* Kite frame K (Sect. II.A, Fig. 3): moves with the kite; origin ``r_k`` at the midpoint of the leading-edge bridle
  points A (right tip) and C (left tip); ``y_k`` points from C to A; ``x_k`` points towards the midpoint of the
  trailing-edge bridle points B and D, orthogonalised against ``y_k``; ``z_k = x_k × y_k`` (away from the bridle,
  the direction into which the loaded wing centre is pushed). The structural and aerodynamic models work in K.
* Section frames i (Sect. II.B, Fig. 4): origin at the section's leading-edge node, ``x`` towards its trailing-edge
  node, ``y`` spanwise (perpendicular to the airfoil plane, towards the right tip), ``z = x × y``
  (built in :mod:`kite_env.aero.sections`).

Rotation matrices ``R_wk`` have the K axes as columns expressed in W: ``v_w = R_wk @ v_k``.
"""

from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along the last axis (explicit components; ``np.cross`` costs ~10 us on 3-vectors)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def kite_frame(pos_a: np.ndarray, pos_b: np.ndarray, pos_c: np.ndarray,
               pos_d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin and orientation of frame K from the bridle points A, B, C, D (each ``(..., 3)`` in any frame F).

    Returns ``origin (..., 3)`` and ``R (..., 3, 3)`` whose columns are ``x_k, y_k, z_k`` expressed in F.
    """
    pos_a, pos_b, pos_c, pos_d = (np.asarray(p, dtype=float) for p in (pos_a, pos_b, pos_c, pos_d))
    origin = 0.5 * (pos_a + pos_c)
    ey = pos_a - pos_c
    ey = ey / np.linalg.norm(ey, axis=-1, keepdims=True)
    ex = 0.5 * (pos_b + pos_d) - origin
    ex = ex - np.sum(ex * ey, axis=-1, keepdims=True) * ey
    ex = ex / np.linalg.norm(ex, axis=-1, keepdims=True)
    ez = cross(ex, ey)
    return origin, np.stack([ex, ey, ez], axis=-1)


def to_frame(vec: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Components in frame K of vectors given in F, for ``R`` from :func:`kite_frame` (``R.T @ vec``)."""
    return np.einsum("...ji,...j->...i", R, vec)


def from_frame(vec_k: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Components in F of vectors given in K (``R @ vec_k``)."""
    return np.einsum("...ij,...j->...i", R, vec_k)


def kite_frame_rates(pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frame K and its motion from the positions and velocities of A, B, C, D (rows of ``pos``, ``vel`` (4, 3)).

    Returns ``origin (3,)``, ``R (3, 3)`` (columns x_k, y_k, z_k), the origin velocity ``v_k = (v_A + v_C) / 2`` and
    the angular velocity ``omega`` of the frame, all in the frame of the input (the wind frame in the flight model).
    ``omega = 1/2 sum_i e_i × de_i/dt`` with the exact time derivatives of the unit vectors of :func:`kite_frame`;
    this is the rotation rate of K itself (the paper's wing state X: v_k, omega_k), not a rigid-body fit of A-D.
    """
    pos = np.asarray(pos, dtype=float)
    vel = np.asarray(vel, dtype=float)
    if pos.shape != (4, 3) or vel.shape != (4, 3):
        raise ValueError(f"kite_frame_rates needs (4, 3) positions and velocities, got {pos.shape}, {vel.shape}")
    return _kite_frame_rates_floats(pos.tolist(), vel.tolist())


def _kite_frame_rates_arrays(pos: np.ndarray, vel: np.ndarray):
    """Reference implementation of :func:`kite_frame_rates` with array operations (kept for the tests)."""
    origin, R = kite_frame(pos[0], pos[1], pos[2], pos[3])
    ex, ey, ez = R[:, 0], R[:, 1], R[:, 2]
    v_k = 0.5 * (vel[0] + vel[2])
    d, dd = pos[0] - pos[2], vel[0] - vel[2]
    ld = np.linalg.norm(d)
    dey = (dd - ey * (ey @ dd)) / ld
    m = 0.5 * (pos[1] + pos[3]) - origin
    dm = 0.5 * (vel[1] + vel[3]) - v_k
    xp = m - (m @ ey) * ey
    dxp = dm - ((dm @ ey) + (m @ dey)) * ey - (m @ ey) * dey
    dex = (dxp - ex * (ex @ dxp)) / np.linalg.norm(xp)
    dez = cross(dex, ey) + cross(ex, dey)
    omega = 0.5 * (cross(ex, dex) + cross(ey, dey) + cross(ez, dez))
    return origin, R, v_k, omega


def _kite_frame_rates_floats(p: list, w: list):
    """:func:`kite_frame_rates` for one set of points, in plain floats (the same formulas; ~20x faster than the
    array code on (4, 3) inputs, which the flight model calls once per time step)."""
    def sub(a, b):
        return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]

    def dot(a, b):
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

    def crs(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    def axpy(a, x, y):  # a x + y
        return [a * x[0] + y[0], a * x[1] + y[1], a * x[2] + y[2]]

    pa, pb, pc, pd = p
    va, vb, vc, vd = w
    origin = [0.5 * (pa[k] + pc[k]) for k in range(3)]
    d = sub(pa, pc)
    ld = dot(d, d) ** 0.5
    ey = [d[k] / ld for k in range(3)]
    m = [0.5 * (pb[k] + pd[k]) - origin[k] for k in range(3)]
    xp = axpy(-dot(m, ey), ey, m)
    lx = dot(xp, xp) ** 0.5
    ex = [xp[k] / lx for k in range(3)]
    ez = crs(ex, ey)
    v_k = [0.5 * (va[k] + vc[k]) for k in range(3)]
    dd = sub(va, vc)
    dey = [(dd[k] - ey[k] * dot(ey, dd)) / ld for k in range(3)]
    dm = [0.5 * (vb[k] + vd[k]) - v_k[k] for k in range(3)]
    my = dot(m, ey)
    c = dot(dm, ey) + dot(m, dey)
    dxp = [dm[k] - c * ey[k] - my * dey[k] for k in range(3)]
    exd = dot(ex, dxp)
    dex = [(dxp[k] - ex[k] * exd) / lx for k in range(3)]
    dez = [a + b for a, b in zip(crs(dex, ey), crs(ex, dey))]
    om = [0.5 * (a + b + c_) for a, b, c_ in zip(crs(ex, dex), crs(ey, dey), crs(ez, dez))]
    R = np.array([[ex[0], ey[0], ez[0]], [ex[1], ey[1], ez[1]], [ex[2], ey[2], ez[2]]])
    return np.array(origin), R, np.array(v_k), np.array(om)
