"""Compiled observation of the figure-eight task for ``n`` kites (used by the single and the batched environment).

:func:`observe_kites` computes, per kite (:func:`_observe_kite`; the single env calls it through :func:`observe_one`,
which takes its step record's arrays as they are and gathers the observation), what
:meth:`KiteFigureEightEnv._observe` needs: the observation terms of
:data:`TERMS` in their canonical order (the env selects its ``env.observation`` terms from them) and the features of
:data:`FEATURES` that the reward and ``info`` use. It includes the nearest point of the figure-eight, the algorithm of
:meth:`kite_env.trajectory.Lemniscate.nearest` step by step: the windowed argmax of ``R . p`` over the precomputed
samples around the previous nearest point (the whole path without one), then the safeguarded Newton refinement of
``Lemniscate._refine`` on ``g = R . p'(s) = 0`` with the curve of ``_curve_scalar``, the same brackets, tolerances
and fallbacks (sample kept when not bracketed or when the refinement does not improve ``R . p``). The sphere helpers
(``heading_angle``, ``sphere_basis``, ``wrap_angle``, ``elevation``, ``azimuth``) are the formulas of
:mod:`kite_env.trajectory` in scalar form, with the same re-normalisations. Results agree with the NumPy reference to
round-off (``tests/envs/test_observe.py``: 1e-12); the only differences are the summation order of 3-term dot
products (BLAS versus a loop).

One compiled call replaces some 60 NumPy calls on 3-vectors (~600 us per step of the single env, measured before
this kernel). The kernel's constants (window, curve parameters, scales) are arguments, not
imports, so that numba's cache (keyed on this file) never holds stale values.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit
from kite_env.trajectory import HINT_WINDOW, Lemniscate

#: observation terms in canonical order with their sizes (the env's ``_TERM_SPECS`` order)
TERMS = (("position", 3), ("heading", 2), ("line_forces", 5), ("path", 5), ("rates", 4), ("actuator", 3))
N_PARTS = sum(n for _, n in TERMS)
#: feature columns of :func:`observe_kites` (``info`` keys of the env, plus ``tracking``: exp(-(delta/scale)^2))
FEATURES = ("t", "path_distance_rad", "path_distance_deg", "path_s", "tether_force_N", "speed_mps", "heading_rad",
            "yaw_rate_rad_s", "force_ratio_mu", "delta_l_m", "elevation_deg", "azimuth_deg", "tracking")
N_FEATURES = len(FEATURES)
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_RAD2DEG = 180.0 / math.pi


def term_indices(layout) -> np.ndarray:
    """Indices into the canonical parts vector (:data:`TERMS`) of the terms named in ``layout`` (in its order)."""
    start, out = {}, []
    i = 0
    for name, n in TERMS:
        start[name] = (i, n)
        i += n
    for name in layout:
        i0, n = start[name]
        out.extend(range(i0, i0 + n))
    return np.asarray(out, dtype=np.int64)


# ---------------------------------------------------------------------------------------------------- kernels
@njit(**JIT)
def _curve_rows(s, a, b, rot, m, out):
    """``_curve_scalar(s, a, b, rot)``: rows p, dp/ds, d2p/ds2 (3, 3) in W into ``out``; ``m`` is scratch."""
    c2 = (a / b) ** 2
    sn, cs = math.sin(s), math.cos(s)
    s2, c2s = 2.0 * sn * cs, cs * cs - sn * sn
    d = 1.0 + c2 * cs * cs
    d1 = -c2 * s2
    d2 = -2.0 * c2 * c2s
    lam = -b * sn / d
    lam1 = (-b * cs - lam * d1) / d
    lam2 = (b * sn - 2.0 * lam1 * d1 - lam * d2) / d
    phi = 0.5 * a * s2 / d
    phi1 = (a * c2s - phi * d1) / d
    phi2 = (-2.0 * a * s2 - 2.0 * phi1 * d1 - phi * d2) / d
    cl, sl, cp, sp = math.cos(lam), math.sin(lam), math.cos(phi), math.sin(phi)
    l11, f11, lf = lam1 * lam1, phi1 * phi1, 2.0 * lam1 * phi1
    m[0, 0] = cl * cp
    m[0, 1] = sl * cp
    m[0, 2] = sp
    m[1, 0] = -sl * cp * lam1 - cl * sp * phi1
    m[1, 1] = cl * cp * lam1 - sl * sp * phi1
    m[1, 2] = cp * phi1
    m[2, 0] = -cl * cp * l11 + sl * sp * lf - cl * cp * f11 - sl * cp * lam2 - cl * sp * phi2
    m[2, 1] = -sl * cp * l11 - cl * sp * lf - sl * cp * f11 + cl * cp * lam2 - sl * sp * phi2
    m[2, 2] = -sp * f11 + cp * phi2
    for i in range(3):  # m @ rot.T
        for j in range(3):
            out[i, j] = m[i, 0] * rot[j, 0] + m[i, 1] * rot[j, 1] + m[i, 2] * rot[j, 2]


@njit(**JIT)
def _row_dot(c, i, x0, x1, x2):
    return c[i, 0] * x0 + c[i, 1] * x1 + c[i, 2] * x2


@njit(**JIT)
def _refine(R0, R1, R2, s0, f0, ds, a, b, rot, m, c):
    """``Lemniscate._refine``: maximise ``R . p(s)`` near the sample ``s0`` by safeguarded Newton on ``R . p' = 0``."""
    lo, hi = s0 - ds, s0 + ds
    _curve_rows(lo, a, b, rot, m, c)
    g_lo = _row_dot(c, 1, R0, R1, R2)
    _curve_rows(hi, a, b, rot, m, c)
    g_hi = _row_dot(c, 1, R0, R1, R2)
    if not (g_lo >= 0.0 >= g_hi):  # not bracketed (far from the path): keep the sample
        return s0
    s = s0
    for _ in range(60):
        _curve_rows(s, a, b, rot, m, c)
        g = _row_dot(c, 1, R0, R1, R2)
        dg = _row_dot(c, 2, R0, R1, R2)
        if g > 0.0:
            lo = s
        else:
            hi = s
        step = -g / dg if dg < 0.0 else math.inf
        if abs(step) < 1e-13:
            s += step
            break
        s_new = s + step
        if not lo < s_new < hi:  # Newton left the bracket: bisect
            s_new = 0.5 * (lo + hi)
        if hi - lo < 1e-13:
            s = s_new
            break
        s = s_new
    _curve_rows(s, a, b, rot, m, c)
    return s if _row_dot(c, 0, R0, R1, R2) >= f0 else s0


@njit(**JIT)
def nearest_point(R0, R1, R2, s_hint, samples, s_samples, window, ds, a, b, rot, m, c):
    """:meth:`Lemniscate.nearest` of the direction ``(R0, R1, R2)`` (any length), ``s_hint`` NaN for none.

    Returns ``(s, distance, p0, p1, p2, t0, t1, t2, n0, n1, n2)``: path parameter in [0, 2 pi), geodesic distance
    [rad], the nearest point, the unit tangent and the normal ``e_n`` (towards the path)."""
    norm = math.sqrt(R0 * R0 + R1 * R1 + R2 * R2)
    R0, R1, R2 = R0 / norm, R1 / norm, R2 / norm
    n = samples.shape[0]
    best = -math.inf
    i_best = 0
    if math.isnan(s_hint):
        for i in range(n):
            d = samples[i, 0] * R0 + samples[i, 1] * R1 + samples[i, 2] * R2
            if d > best:
                best = d
                i_best = i
    else:
        centre = int(np.rint((s_hint % _TWO_PI) / ds))
        for j in range(-window, window + 1):
            i = (centre + j) % n
            d = samples[i, 0] * R0 + samples[i, 1] * R1 + samples[i, 2] * R2
            if d > best:
                best = d
                i_best = i
    s = _refine(R0, R1, R2, s_samples[i_best], best, ds, a, b, rot, m, c)
    _curve_rows(s, a, b, rot, m, c)
    p0, p1, p2 = c[0, 0], c[0, 1], c[0, 2]
    dn = math.sqrt(c[1, 0] * c[1, 0] + c[1, 1] * c[1, 1] + c[1, 2] * c[1, 2])
    t0, t1, t2 = c[1, 0] / dn, c[1, 1] / dn, c[1, 2] / dn
    l0, l1, l2 = p1 * t2 - p2 * t1, p2 * t0 - p0 * t2, p0 * t1 - p1 * t0  # left = p x e_t
    x0, x1, x2 = R1 * p2 - R2 * p1, R2 * p0 - R0 * p2, R0 * p1 - R1 * p0  # R x p
    dist = math.atan2(math.sqrt(x0 * x0 + x1 * x1 + x2 * x2), R0 * p0 + R1 * p1 + R2 * p2)
    side = R0 * l0 + R1 * l1 + R2 * l2  # > 0: the kite is on the left of the path
    if side > 1e-12:
        l0, l1, l2 = -l0, -l1, -l2
    return s % _TWO_PI, dist, p0, p1, p2, t0, t1, t2, l0, l1, l2


@njit(**JIT)
def _sphere_basis(r0, r1, r2):
    """:func:`kite_env.trajectory.sphere_basis` at ``r / |r|`` for one vector: ``x_s`` then ``y_s``."""
    n = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    r0, r1, r2 = r0 / n, r1 / n, r2 / n
    h = math.hypot(r0, r1)
    if h > 0.0:
        cp, sp = r0 / h, r1 / h
    else:
        cp, sp = 1.0, 0.0
    xs0, xs1, xs2 = -r2 * cp, -r2 * sp, h
    return xs0, xs1, xs2, r1 * xs2 - r2 * xs1, r2 * xs0 - r0 * xs2, r0 * xs1 - r1 * xs0


@njit(**JIT)
def _heading(r0, r1, r2, v0, v1, v2):
    """:func:`kite_env.trajectory.heading_angle` of one vector (scalar branch)."""
    xs0, xs1, xs2, ys0, ys1, ys2 = _sphere_basis(r0, r1, r2)
    psi = math.atan2(v0 * ys0 + v1 * ys1 + v2 * ys2, v0 * xs0 + v1 * xs1 + v2 * xs2)
    return _PI if psi <= -_PI else psi


@njit(**JIT)
def _wrap(x):
    """:func:`kite_env.trajectory.wrap_angle` of a float: (-pi, pi]."""
    w = _PI - (_PI - x) % _TWO_PI
    return w + _TWO_PI if w <= -_PI else w


@njit(**JIT)
def _observe_kite(x0, x1, x2, u0, u1, u2, nose0, nose1, nose2, zk0, zk1, zk2, om0, om1, om2, vk0, vk1, vk2, T0, T1,
                  T2, T3, l_B, l_D, tether, t, s_hint, last_action, samples, s_samples, window, ds, a, b, rot,
                  force_scale, dl_max, tracking_scale, m, c, q, f):
    """One kite of :func:`observe_kites` from its values: KCU position ``x`` and velocity ``u``, the nose ``-x_k``
    and ``z_k`` of frame K, ``omega``, ``v_kite``, the tensions ``T0..T3`` and the lengths of the lines B and D, the
    tether force, ``t``, the hint and the last action (all in W). Writes the terms ``q`` (22,) and the features ``f``
    (13,); returns the nearest path parameter (the next hint). ``m``, ``c`` (3, 3): scratch."""
    n_r = math.sqrt(x0 ** 2 + x1 ** 2 + x2 ** 2)
    R0, R1, R2 = x0 / n_r, x1 / n_r, x2 / n_r
    psi = _heading(R0, R1, R2, nose0, nose1, nose2)
    s, dist, p0, p1, p2, t0, t1, t2, n0, n1, n2 = nearest_point(R0, R1, R2, s_hint, samples, s_samples, window, ds,
                                                               a, b, rot, m, c)
    l0, l1, l2 = p1 * t2 - p2 * t1, p2 * t0 - p0 * t2, p0 * t1 - p1 * t0
    signed = -dist * math.copysign(1.0, n0 * l0 + n1 * l1 + n2 * l2)
    psi_t = _heading(p0, p1, p2, t0, t1, t2)
    dpsi = _wrap(psi_t - psi)
    xs0, xs1, xs2, ys0, ys1, ys2 = _sphere_basis(R0, R1, R2)  # with its own re-normalisation, as sphere_basis
    vr = u0 * R0 + u1 * R1 + u2 * R2
    w0 = (u0 - vr * R0) / n_r  # angular rate on the unit sphere (n_r = l_t, also while reeling)
    w1 = (u1 - vr * R1) / n_r
    w2 = (u2 - vr * R2) / n_r
    yaw = zk0 * om0 + zk1 * om1 + zk2 * om2
    speed = math.sqrt(vk0 ** 2 + vk1 ** 2 + vk2 ** 2)
    mu = (T1 + T3) / max(T0 + T2, 1e-9)  # Eq. (18), LineActuator.force_ratio
    dl = l_B - l_D
    tf = tether if math.isfinite(tether) else (((T0 + T1) + T2) + T3)
    q[0], q[1], q[2] = R0, R1, R2
    q[3], q[4] = math.sin(psi), math.cos(psi)
    q[5], q[6], q[7], q[8], q[9] = T0 / force_scale, T1 / force_scale, T2 / force_scale, T3 / force_scale, \
        tf / force_scale
    q[10], q[11], q[12], q[13], q[14] = signed, math.sin(dpsi), math.cos(dpsi), math.sin(s), math.cos(s)
    q[15] = w0 * xs0 + w1 * xs1 + w2 * xs2
    q[16] = w0 * ys0 + w1 * ys1 + w2 * ys2
    q[17], q[18] = yaw, speed / 25.0  # V_SCALE_MPS
    q[19], q[20], q[21] = last_action, dl / dl_max, mu
    f[0], f[1], f[2], f[3] = t, dist, dist * _RAD2DEG, s
    f[4], f[5], f[6], f[7], f[8], f[9] = tf, speed, psi, yaw, mu, dl
    f[10] = math.atan2(R2, math.hypot(R0, R1)) * _RAD2DEG
    f[11] = math.atan2(R1, R0) * _RAD2DEG
    f[12] = math.exp(-((dist / tracking_scale) * (dist / tracking_scale)))
    return s


@njit(**JIT)
def observe_kites(active, r_kcu, v_kcu, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action,
                  samples, s_samples, window, ds, a, b, rot, force_scale, dl_max, tracking_scale,
                  parts, feats):
    """Observation terms and features of every ``active`` kite (:meth:`KiteFigureEightEnv._observe` for n kites).

    Parameters
    ----------
    active : (n,) bool
    r_kcu, v_kcu : (n, 3) float [m], [m/s], KCU position and velocity in W
    R_wk : (n, 3, 3) float, frame K in W (columns x_k, y_k, z_k)
    omega : (n, 3) float [rad/s], angular velocity of K in W
    v_kite : (n, 3) float [m/s], velocity of the origin of K
    tension, length : (n, 4) float [N], [m], bridle lines A, B, C, D
    tether : (n,) float [N], tether force (NaN: the sum of the line tensions stands in, as at a reset)
    t : (n,) float [s]
    s_hint : (n,) float [rad], previous nearest path parameter (NaN: none); updated in place
    last_action : (n,) float, the actuator term's last action
    samples, s_samples, window, ds, a, b, rot : the path (:class:`Lemniscate` samples, window half width in
        samples, sample spacing, chart parameters, rotation)
    force_scale, dl_max, tracking_scale : [N], [m], [rad]
    parts : (n, 22) float, out: terms of :data:`TERMS`; feats : (n, 13) float, out: :data:`FEATURES`
    """
    m = np.empty((3, 3))
    c = np.empty((3, 3))
    for k in range(r_kcu.shape[0]):
        if not active[k]:
            continue
        s_hint[k] = _observe_kite(r_kcu[k, 0], r_kcu[k, 1], r_kcu[k, 2], v_kcu[k, 0], v_kcu[k, 1], v_kcu[k, 2],
                                  -R_wk[k, 0, 0], -R_wk[k, 1, 0], -R_wk[k, 2, 0], R_wk[k, 0, 2], R_wk[k, 1, 2],
                                  R_wk[k, 2, 2], omega[k, 0], omega[k, 1], omega[k, 2], v_kite[k, 0], v_kite[k, 1],
                                  v_kite[k, 2], tension[k, 0], tension[k, 1], tension[k, 2], tension[k, 3],
                                  length[k, 1], length[k, 3], tether[k], t[k], s_hint[k], last_action[k], samples,
                                  s_samples, window, ds, a, b, rot, force_scale, dl_max, tracking_scale, m, c,
                                  parts[k], feats[k])


@njit(**JIT)
def observe_one(r, v, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action, samples, s_samples,
                window, ds, a, b, rot, force_scale, dl_max, tracking_scale, index, parts, feats, obs):
    """:func:`observe_kites` of one kite from the arrays of its step record (the single env), with the observation
    gathered: ``r``, ``v`` (5, 3) the masses (KCU last), ``R_wk`` (3, 3), ``omega``, ``v_kite`` (3,), ``tension``,
    ``length`` (4,), floats ``tether``, ``t``, ``s_hint``, ``last_action``; the path and scales as there. Writes
    ``parts`` (22,), ``feats`` (13,) and ``obs[i] = float32(parts[index[i]])``; returns the new hint and whether
    every entry of ``obs`` is finite (the same values as a batch of one: one code per kite)."""
    m = np.empty((3, 3))
    c = np.empty((3, 3))
    s = _observe_kite(r[4, 0], r[4, 1], r[4, 2], v[4, 0], v[4, 1], v[4, 2], -R_wk[0, 0], -R_wk[1, 0], -R_wk[2, 0],
                      R_wk[0, 2], R_wk[1, 2], R_wk[2, 2], omega[0], omega[1], omega[2], v_kite[0], v_kite[1],
                      v_kite[2], tension[0], tension[1], tension[2], tension[3], length[1], length[3], tether, t,
                      s_hint, last_action, samples, s_samples, window, ds, a, b, rot, force_scale, dl_max,
                      tracking_scale, m, c, parts, feats)
    finite = True
    for i in range(index.shape[0]):
        x = np.float32(parts[index[i]])
        obs[i] = x
        if not math.isfinite(x):
            finite = False
    return s, finite


# ---------------------------------------------------------------------------------------------------- wrapper
class Observer:
    """The path and scales of one configuration, bound to :func:`observe_kites`.

    Parameters
    ----------
    cfg : Config
    path : Lemniscate
    layout : iterable of term names (the env's ``env.observation``)
    """

    def __init__(self, cfg, path: Lemniscate, layout):
        self.path = path
        self.index = term_indices(list(layout))
        self.samples = np.ascontiguousarray(path.samples, dtype=float)
        self.s_samples = np.ascontiguousarray(path.s_samples, dtype=float)
        self.window = int(HINT_WINDOW / path.ds)
        #: the path and scales in the order of observe_one's arguments after ``last_action`` (the compiled step
        #: of the single fast env takes them too, kite_env.envs.fast_step)
        self.consts = (self.samples, self.s_samples, self.window, float(path.ds), float(path.a), float(path.b),
                        np.ascontiguousarray(path.rotation, dtype=float),
                        float(cfg.env.force_scale_N), float(cfg.control.delta_l_max_m),
                        math.radians(cfg.env.tracking_scale_deg))

    def __call__(self, active, r_kcu, v_kcu, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action,
                 parts, feats):
        """:func:`observe_kites` with this path and these scales (arguments as there)."""
        observe_kites(active, r_kcu, v_kcu, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action,
                      *self.consts, parts, feats)

    def one(self, r, v, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action, parts, feats, obs):
        """:func:`observe_one` with this path, these scales and the observation's ``index`` (arguments as there)."""
        return observe_one(r, v, R_wk, omega, v_kite, tension, length, tether, t, s_hint, last_action, *self.consts,
                           self.index, parts, feats, obs)
