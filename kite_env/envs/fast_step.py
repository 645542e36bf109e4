"""One control step of the fast single env (``KiteFigureEightFast-v1``) in one compiled call.

:meth:`KiteFigureEightEnv.step` of the surrogate fidelity spent most of its time in Python around the physics: the
actuator, two calls of :func:`kite_env.dynamics.fast.step_kites` with some 50 arguments each (numba unboxes every
argument at every call), a step record per physics step, the observation's call and the reward terms.
:func:`control_step` does all of it in one call: the actuator (:meth:`kite_env.control.LineActuator.rest_lengths`),
the ``n_physics`` physics steps of the one kite with the env's ends (a failed physics step, the ground, a slack
tether), the observation of the last good state (:func:`kite_env.envs.observe.observe_one`, with ``omega`` as the
record computes it), its finiteness, clip and the reward terms (:func:`kite_env.envs.figure_eight.reward_terms`).
Every operation is the one of the Python step, in the same order, so the flight is the same bit for bit
(``tests/envs/test_scalar_paths.py``); the env keeps in Python only what the Gymnasium API needs (the action's
check, the ``info`` dict, the step record, built when read).

The observation reads ``omega = R_wk @ X[27:30]``: NumPy hands this 3 x 3 product to OpenBLAS, whose kernel on this
machine (x86-64 with FMA) computes each row as ``fma(R[i, 2], w2, fma(R[i, 0], w0, R[i, 1] w1))``.
:func:`kite_omega` is that order, with an explicit FMA (:func:`kite_env.compiled.fma`), so the compiled step gives
the observations NumPy gave, and the batched env (:mod:`kite_env.envs.vector`) computes its ``omega`` with the same
function, so that the batch and the single env agree on any machine, whatever its BLAS.

numba's cache is keyed on this file: a change of a kernel it calls in another file (``step_kites``,
``observe_one``) needs this file's cache cleared as well (:mod:`kite_env.compiled`).
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, fma, njit
from kite_env.dynamics.fast import NON_FINITE, OK, kite_views, step_kites_with, step_work
from kite_env.envs.observe import observe_one

#: ``code`` of :func:`control_step` (``out[0]``): how the step ended
NONE, GROUND, SLACK, NON_FINITE_PARTICLES, OUTSIDE_ENVELOPE, NON_FINITE_OBS, BAD_REST = 0, 1, 2, 3, 4, 5, 6
#: the env's ``termination_reason`` of each code
REASONS = (None, "ground", "slack tether", "non-finite particle state", "outside surrogate envelope",
           "non-finite state", None)
#: ``out`` of :func:`control_step`
(O_CODE, O_L_B, O_L_D, O_DLS, O_INTEGRAL, O_HINT, O_FINITE, O_TRACKING, O_TRACTION, O_ACTION, O_CRASH, O_REWARD,
 O_KCU) = range(13)
N_OUT = O_KCU + 3
#: ``ctrl`` of :func:`control_step`: the control section's constants
(C_DL_MAX_ACTION, C_DL_MAX, C_K2, C_K3, C_K3I, C_MU_TARGET, C_INTEGRAL_MAX, C_CONTROL_DT, C_LINE_SPEED_MAX,
 C_POWER_MIN) = range(10)
#: ``envp`` of :func:`control_step`: the env's constants
(E_N_PHYSICS, E_SIN_GROUND, E_SLACK_ENDS, E_SLACK_N, E_W_TRACKING, E_W_TRACTION, E_TRACTION_REF, E_W_ACTION,
 E_CRASH) = range(9)


@njit(**JIT)
def kite_omega(R, w, out):
    """``out = R @ w`` for ``R`` (3, 3), ``w`` (3,), each row in the order of OpenBLAS's kernel (module docstring)."""
    for i in range(3):
        out[i] = fma(R[i, 2], w[2], fma(R[i, 0], w[0], R[i, 1] * w[1]))


@njit(**JIT)
def kite_omega_rows(R, X, out):
    """:func:`kite_omega` of every kite: ``out[k] = R[k] @ X[k, 27:30]`` (the rotation rate in W from the inputs'
    rate in K)."""
    for k in range(R.shape[0]):
        for i in range(3):
            out[k, i] = fma(R[k, i, 2], X[k, 29], fma(R[k, i, 0], X[k, 27], R[k, i, 1] * X[k, 28]))


@njit(**JIT)
def _clip(x, lo, hi):
    """:func:`kite_env.control._clip` (NumPy's clip of floats, its NaN and zero rules)."""
    m = x if (x != x or x >= lo) else lo
    if m != m:
        return m
    return hi if (hi != hi or hi < m) else m


@njit(**JIT)
def rest_lengths(delta_l_star, ctrl, L_B0, L_D0, integral, L_B_prev, L_D_prev, T0, T1, T2, T3, l1, l3):
    """:meth:`kite_env.control.LineActuator.rest_lengths` of floats: ``(L_B, L_D, delta_l_star clipped, integral)``
    from the actuator's state (``L_B0``, ``L_D0``, the force loop's ``integral``, the last rest lengths), the
    tensions ``T0..T3`` and the lengths ``l1``, ``l3`` of the lines B and D; ``ctrl`` as :func:`control_step`."""
    dls = _clip(delta_l_star, -ctrl[C_DL_MAX], ctrl[C_DL_MAX])
    dl = l1 - l3
    mu_target = ctrl[C_MU_TARGET]
    k3i = ctrl[C_K3I]
    power = T0 + T2
    mu = (T1 + T3) / power if power >= ctrl[C_POWER_MIN] else mu_target
    err = mu_target - mu
    if k3i <= 0.0:
        integral = integral * 0.0
    else:
        lim = ctrl[C_INTEGRAL_MAX] / k3i
        integral = _clip(integral + err * ctrl[C_CONTROL_DT], -lim, lim)
    L3 = -ctrl[C_K3] * err - k3i * integral
    e = dls - dl
    k2 = ctrl[C_K2]
    L_B = L_B0 + k2 * e + L3
    L_D = L_D0 - k2 * e + L3
    if ctrl[C_LINE_SPEED_MAX] > 0.0:
        step = ctrl[C_LINE_SPEED_MAX] * ctrl[C_CONTROL_DT]
        c_prev, d_prev = 0.5 * (L_B_prev + L_D_prev), 0.5 * (L_B_prev - L_D_prev)
        c = _clip(0.5 * (L_B + L_D), c_prev - step, c_prev + step)
        d = _clip(0.5 * (L_B - L_D), d_prev - step, d_prev + step)
        L_B, L_D = c + d, c - d
    return L_B, L_D, dls, integral


#: the snapshot of the last good state (:func:`control_step`'s ``snap``): offsets of t, r, v, R, tension, length,
#: tether force, tether length, reel speed, Y, X
S_T, S_R, S_V, S_RK, S_TENSION, S_LENGTH, S_TETHER, S_TETHER_LENGTH, S_REEL, S_Y, S_X = (0, 1, 16, 31, 40, 44, 48, 49,
                                                                                      50, 51, 68)


@njit(**JIT)
def _save(snap, t, r, v, R, tension, length, tether, tether_length, reel_speed, Y, X):
    """The record's arrays of kite 0 into ``snap`` (offsets ``S_*``)."""
    snap[S_T] = t[0]
    for i in range(5):
        for c in range(3):
            snap[S_R + 3 * i + c] = r[0, i, c]
            snap[S_V + 3 * i + c] = v[0, i, c]
    for i in range(3):
        for c in range(3):
            snap[S_RK + 3 * i + c] = R[0, i, c]
    for i in range(4):
        snap[S_TENSION + i] = tension[0, i]
        snap[S_LENGTH + i] = length[0, i]
    snap[S_TETHER] = tether[0]
    snap[S_TETHER_LENGTH] = tether_length[0]
    snap[S_REEL] = reel_speed[0]
    for j in range(Y.shape[1]):
        snap[S_Y + j] = Y[0, j]
    for j in range(X.shape[1]):
        snap[S_X + j] = X[0, j]


#: the env's arrays of :func:`control_step` (``ef``, float64, in this order; ``ei`` holds, after the number of path
#: samples and the snapshot's size, their offsets in ``ef``, then the observation's term indices): the constants
#: ``ctrl`` and ``envp``, the path samples (N, 3), their parameters (N,), the path rotation (3, 3), the observer's
#: scalars (window, spacing, chart a and b, force scale, steering scale, tracking scale), then the outputs ``parts``,
#: ``feats``, ``snap``, ``out``
ENV_F64 = ("ctrl", "envp", "samples", "s_samples", "rot", "scalars", "parts", "feats", "snap", "out")
_EI_OFF = 2
_EI_INDEX = _EI_OFF + len(ENV_F64)


@njit(**JIT)
def control_step(a, prev_action, s_hint, L_B0, L_D0, integral, L_B_prev, L_D_prev, ef, ei, ew, obs, dt, active, kf,
                 ki, kw, klay):
    """:func:`control_step_of` with the env's arrays packed in ``ef`` (float64), ``ei`` (int64: sizes, offsets, the
    observation's indices, :data:`ENV_F64`), ``ew`` (float32: the observation's lower then upper bounds) and the
    kite's in the buffers of :meth:`kite_env.dynamics.fast.SurrogateKites.pack` (``kf``, ``ki``, ``kw``, ``klay``):
    18 arguments instead of some 80 (numba unboxes every argument at every call)."""
    n_s, n_snap = ei[0], ei[1]
    o = ei[_EI_OFF:_EI_INDEX]
    n_obs = obs.shape[0]
    index = ei[_EI_INDEX:_EI_INDEX + n_obs]
    sc = ef[o[5]:o[5] + 7]
    control_step_of(a, prev_action, s_hint, L_B0, L_D0, integral, L_B_prev, L_D_prev, ef[o[0]:o[0] + 10],
                    ef[o[1]:o[1] + 9], ef[o[2]:o[2] + 3 * n_s].reshape((n_s, 3)), ef[o[3]:o[3] + n_s], int(sc[0]),
                    sc[1], sc[2], sc[3], ef[o[4]:o[4] + 9].reshape((3, 3)), sc[4], sc[5], sc[6], index, ew[:n_obs],
                    ew[n_obs:2 * n_obs], ef[o[6]:o[6] + 22], ef[o[7]:o[7] + 13], obs, ef[o[8]:o[8] + n_snap],
                    ef[o[9]:o[9] + N_OUT], dt, active, *kite_views(kf, ki, kw, klay))


@njit(**JIT)
def control_step_of(a, prev_action, s_hint, L_B0, L_D0, integral, L_B_prev, L_D_prev, ctrl, envp, samples, s_samples,
                    window, ds, path_a, path_b, rot, force_scale, dl_max, tracking_scale, index, low, high, parts,
                    feats, obs, snap, out, dt, active, t, r, v, rest, pair_damping, q_design, wind_f, wind_i, wavevec_t,
                    phase0, omega_m, amp, n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho, line_cd, line_diameter,
                    tether_diameter, tether_length, reel_speed, winch, tip_lengths, gravity, alpha, lo, hi, X, Y, wind,
                    turb, R, tether, tension, length, status, Z, sel, gain, K_b):
    """One control step of the single fast env (:meth:`KiteFigureEightEnv.step`) for the action ``a`` (a float in
    [-1, 1]).

    ``prev_action``, ``s_hint``: the env's last action and nearest-point hint; ``L_B0 .. L_D_prev``: the actuator's
    state (:class:`kite_env.control.LineActuator`); ``ctrl`` (``C_*``) and ``envp`` (``E_*``): constants of the
    control section and the env; ``samples .. tracking_scale``: the path and scales of
    :class:`kite_env.envs.observe.Observer`, ``index`` the observation's terms, ``low``/``high`` its bounds (float32);
    ``parts``, ``feats``: out, as :func:`kite_env.envs.observe.observe_one`; ``obs`` (float32): out, the clipped
    observation; ``snap``: out, the last good state (offsets ``S_*``); ``out`` (:data:`N_OUT`): out, ``O_*``. The
    rest are the arguments of :func:`kite_env.dynamics.fast.step_kites` for one kite (its state advanced in place;
    after a failed physics step it is the failed state, the observation that of ``snap``).

    Returns nothing; ``out[O_CODE]`` is :data:`BAD_REST` (rest lengths not positive and finite, nothing stepped, as
    :meth:`SurrogateFlightSimulator.step` refuses them) or the end of the step (:data:`NONE`, :data:`GROUND`, ...).
    """
    # ---- the actuator (LineActuator.rest_lengths), from the lines of the current (last good) state
    L_B, L_D, dls, integral = rest_lengths(a * ctrl[C_DL_MAX_ACTION], ctrl, L_B0, L_D0, integral, L_B_prev, L_D_prev,
                                           tension[0, 0], tension[0, 1], tension[0, 2], tension[0, 3], length[0, 1],
                                           length[0, 3])
    out[O_L_B], out[O_L_D], out[O_DLS], out[O_INTEGRAL] = L_B, L_D, dls, integral
    if not (L_B > 0 and L_D > 0 and math.isfinite(L_B) and math.isfinite(L_D)):
        out[O_CODE] = BAD_REST
        return
    # ---- the physics steps with the env's ends (KiteFigureEightEnv.step)
    code = NONE
    good = True  # the live state is the last good one (no physics step failed)
    sin_ground = envp[E_SIN_GROUND]
    work = step_work(X.shape[1], Y.shape[1], W0, W1, W2)  # once for the physics steps
    for _ in range(int(envp[E_N_PHYSICS])):
        _save(snap, t, r, v, R, tension, length, tether, tether_length, reel_speed, Y, X)
        rest[0, 1] = L_B
        rest[0, 3] = L_D
        step_kites_with(work, dt, active, t, r, v, rest, pair_damping, q_design, wind_f, wind_i, wavevec_t, phase0,
                        omega_m, amp, n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho, line_cd, line_diameter,
                        tether_diameter, tether_length, reel_speed, winch, tip_lengths, gravity, alpha, lo, hi, X, Y,
                        wind, turb, R, tether, tension, length, status, Z, sel, gain, K_b)
        if status[0] != OK:
            code = NON_FINITE_PARTICLES if status[0] == NON_FINITE else OUTSIDE_ENVELOPE
            good = False
            break
        x, y, z = r[0, 4, 0], r[0, 4, 1], r[0, 4, 2]
        if z < sin_ground * math.sqrt(x * x + y * y + z * z):
            code = GROUND
            break
        if envp[E_SLACK_ENDS] != 0.0 and tether[0] < envp[E_SLACK_N]:
            code = SLACK
            break
    # ---- the observation of the last good state (observe_one of its record)
    if good:
        rs, vs, Rs, Xs = r[0], v[0], R[0], X[0]
        Ts, ls = tension[0], length[0]
        tf, tk = tether[0], t[0]
    else:
        rs = snap[S_R:S_R + 15].reshape((5, 3))
        vs = snap[S_V:S_V + 15].reshape((5, 3))
        Rs = snap[S_RK:S_RK + 9].reshape((3, 3))
        Xs = snap[S_X:S_X + X.shape[1]]
        Ts = snap[S_TENSION:S_TENSION + 4]
        ls = snap[S_LENGTH:S_LENGTH + 4]
        tf, tk = snap[S_TETHER], snap[S_T]
    om = np.empty(3)
    kite_omega(Rs, Xs[27:30], om)
    vk = np.empty(3)
    vk[0] = 0.5 * (vs[0, 0] + vs[2, 0])
    vk[1] = 0.5 * (vs[0, 1] + vs[2, 1])
    vk[2] = 0.5 * (vs[0, 2] + vs[2, 2])
    out[O_HINT], finite = observe_one(rs, vs, Rs, om, vk, Ts, ls, tf, tk, s_hint, a, samples, s_samples, window, ds,
                                      path_a, path_b, rot, force_scale, dl_max, tracking_scale, index, parts, feats,
                                      obs)
    if code == NONE and not finite:
        code = NON_FINITE_OBS
    out[O_CODE] = code
    out[O_FINITE] = 1.0 if finite else 0.0
    for c in range(3):
        out[O_KCU + c] = rs[4, c]
    # ---- reward terms (reward_terms of floats) and their sum (float(sum(terms.values())))
    failed = code != NONE
    d = a - prev_action
    r_track = 0.0 if failed else envp[E_W_TRACKING] * feats[12]
    r_tract = 0.0 if failed else envp[E_W_TRACTION] * feats[4] / envp[E_TRACTION_REF]
    r_action = -envp[E_W_ACTION] * (d * d)
    r_crash = -envp[E_CRASH] if failed else 0.0
    out[O_TRACKING], out[O_TRACTION], out[O_ACTION], out[O_CRASH] = r_track, r_tract, r_action, r_crash
    out[O_REWARD] = (((0.0 + r_track) + r_tract) + r_action) + r_crash
    # ---- the observation as the env returns it: non-finite entries zeroed (np.nan_to_num), clipped as
    # ndarray.clip clips float32 (a bound equal to the value replaces it: the sign of a zero bound wins)
    for i in range(index.shape[0]):
        q = obs[i]
        if not math.isfinite(q):
            q = np.float32(0.0)
        if not q > low[i]:
            q = low[i]
        if not q < high[i]:
            q = high[i]
        obs[i] = q
