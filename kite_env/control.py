"""Steering-line actuation: the K2 loops of the steering controller and the force controller (Bosch et al., Sect. III).

The steering controller of the paper has two levels. The outer level turns the heading error into a desired
steering-line length difference ``dl* = K1 (psi* - psi)`` (Eq. 15; :mod:`kite_env.policies.baseline`, and the action
of the Gymnasium environment). The inner level, implemented here, sets the rest lengths of the right (B) and left (D)
steering-line springs from the error of the actual difference ``dl = l_B - l_D`` (Eq. 16-17), and the force
controller adds the same increment to both (Eq. 18-19):

    L_B = L_B,0 + K2 (dl* - dl) + L3
    L_D = L_D,0 - K2 (dl* - dl) + L3,        L3 = -K3 (mu* - mu) - K3i I,   mu = (F_cB + F_cD) / (F_cA + F_cC)

with ``I = int (mu* - mu) dt`` (``control.k3i_per_s``; 0 = the paper's proportional force controller, Eq. 19).

Why an integral term. The paper's force loop is proportional; its gain is not given. In a turn the steering input
``dL = L_B - L_D`` is split symmetrically, so the released line is paid out by ``dL / 2``; when that exceeds its
stretch (about 0.3-0.8 m at 3-4 kN per line, k_c = 4.52 kN/m) the line goes slack, the released tip's trailing edge
is free and the tip luffs down to -60 deg (measured), and mu falls. A proportional loop holds mu only with a gain
large enough to limit-cycle at the controller rate (K3 = 1 m); the integral term shortens both steering lines until
mu is back at mu*, i.e. until the released line carries its share again, as the common-mode (depower) actuation of a
KCU does. The integral is clamped to +-``control.force_integral_max_m`` (anti-windup).

Sign of the K2 loop. Eq. (16-17) as printed read ``L_B = L_B,0 - K2 (dl* - dl)``, ``L_D = L_D,0 + K2 (dl* - dl)``
with ``dl = l_B - l_D``: for K2 > 0 that lengthens the left and shortens the right line when ``dl`` should grow,
which moves ``dl`` away from ``dl*`` (positive feedback). We use the sign that closes the loop (equivalently K2 < 0
in the printed form); the paper's text ("proportional controllers ... to control the individual steering line
lengths") leaves no doubt about the intent.

Sign of the force loop, Eq. (19) as printed: ``L3 = -K3 (mu* - mu)`` with K3 > 0. With mu below mu* both steering
lines get shorter; pulling both rear lines pitches the wing up (larger angle of attack) and moves load from the
power lines to the steering lines, which raises mu.
"""

from __future__ import annotations

import numpy as np

from kite_env.config import ControlConfig

# Below this tension of the power lines (F_cA + F_cC) the force ratio of Eq. 18 is not defined (an unloaded wing,
# slack bridle lines: 0/0); the force loop then holds (error 0) instead of acting on a ratio of two noise levels.
# Without it, a luffing wing whose power lines carry 1e-9 N while a steering line carries 1 N gave mu = 1e9 and
# rest lengths of 1e10 m (the constant:1 flight of the wing with inertia on a rope tether, docs/model.md, "Large
# steering inputs").
POWER_LINES_MIN_N = 100.0


def force_ratio_error(T, mu_target: float):
    """``(mu, mu* - mu)`` from line tensions ``T`` (..., 4) in the order A, B, C, D (Eq. 18); where the power lines
    carry less than :data:`POWER_LINES_MIN_N` the error is 0 and mu is reported as mu*. Works on floats and arrays."""
    T = np.asarray(T, dtype=float)
    power = T[..., 0] + T[..., 2]
    loaded = power >= POWER_LINES_MIN_N
    mu = np.where(loaded, (T[..., 1] + T[..., 3]) / np.maximum(power, POWER_LINES_MIN_N), mu_target)
    return mu, mu_target - mu


class LineActuator:
    """Steering-line rest lengths from a desired length difference (Eq. 16-17) and the force ratio (Eq. 18-19).

    Parameters
    ----------
    cfg : ControlConfig
    L_B0, L_D0 : float [m]
        Initial rest lengths of the right and left steering lines.
    """

    def __init__(self, cfg: ControlConfig, L_B0: float, L_D0: float):
        self.cfg = cfg
        self.L_B0 = float(L_B0)
        self.L_D0 = float(L_D0)
        self.integral = 0.0  # I = int (mu* - mu) dt [s], see the module docstring
        self.last = (self.L_B0, self.L_D0)  # rest lengths of the last period (the actuator's speed limit)
        #: an exogenous common offset of both steering lines [m] on top of the force loop (0: the paper's actuator):
        #: the excitation of depower that identification needs (kite_env.fitting.trajectories.HeldDepower) and the
        #: input of the depower response (analyses/steering_response.py); set before each controller period
        self.depower_offset_m = 0.0

    @staticmethod
    def force_ratio(line_tension: np.ndarray) -> float:
        """mu = (F_cB + F_cD) / (F_cA + F_cC), Eq. (18); lines in the order A, B, C, D."""
        T = np.asarray(line_tension, dtype=float)
        return float((T[1] + T[3]) / max(T[0] + T[2], 1e-9))

    def force_increment(self, line_tension: np.ndarray) -> tuple[float, float]:
        """The force loop over one controller period: ``(L3, mu)``, the common increment of both steering-line rest
        lengths [m] (Eq. 19 plus the integral term) and the force ratio of Eq. (18); advances the integral."""
        cfg = self.cfg
        T0, T1, T2, T3 = _four_floats(line_tension)
        # force_ratio_error and force_integral in float arithmetic (one actuator per step of the single env, where
        # NumPy's per-call cost on 0-d values was most of the controller's time); the same operations, bit for bit
        power = T0 + T2
        mu = (T1 + T3) / power if power >= POWER_LINES_MIN_N else float(cfg.mu_target)
        err = cfg.mu_target - mu
        if cfg.k3i_per_s <= 0.0:
            self.integral = self.integral * 0.0
        else:
            lim = cfg.force_integral_max_m / cfg.k3i_per_s
            self.integral = _clip(self.integral + err * cfg.control_dt_s, -lim, lim)
        return -cfg.k3_m * err - cfg.k3i_per_s * self.integral, mu  # Eq. (19), plus the integral

    def rest_lengths(self, delta_l_star: float, line_length: np.ndarray, line_tension: np.ndarray):
        """Rest lengths ``(L_B, L_D)`` [m] and a dict with ``delta_l``, ``mu``, ``L3``.

        ``delta_l_star`` [m] is clipped to ``+-control.delta_l_max_m``; ``line_length`` and ``line_tension`` are the
        current lengths and tensions of the lines A, B, C, D. One call is one controller period
        (``control.control_dt_s``): it advances the force loop's integral, and the actuator moves from the last
        period's rest lengths at most at ``control.line_speed_max_mps`` (:func:`actuate`).
        """
        cfg = self.cfg
        if type(delta_l_star) is float:
            dls = _clip(delta_l_star, -cfg.delta_l_max_m, cfg.delta_l_max_m)
        else:  # a NumPy value clips in its own precision
            dls = float(np.clip(delta_l_star, -cfg.delta_l_max_m, cfg.delta_l_max_m))
        _, l1, _, l3 = _four_floats(line_length)
        dl = l1 - l3  # Delta l = l_B - l_D (Sect. III.A)
        L3, mu = self.force_increment(line_tension)
        e = dls - dl
        L_B0, L_D0 = self.L_B0, self.L_D0
        if self.depower_offset_m:
            L_B0, L_D0 = L_B0 + self.depower_offset_m, L_D0 + self.depower_offset_m
        L_B = L_B0 + cfg.k2 * e + L3  # Eq. (16), sign closing the loop (module docstring)
        L_D = L_D0 - cfg.k2 * e + L3  # Eq. (17)
        if cfg.line_speed_max_mps > 0.0:  # actuate() in float arithmetic
            step = cfg.line_speed_max_mps * cfg.control_dt_s
            L_B_prev, L_D_prev = self.last
            c_prev, d_prev = 0.5 * (L_B_prev + L_D_prev), 0.5 * (L_B_prev - L_D_prev)
            c = _clip(0.5 * (L_B + L_D), c_prev - step, c_prev + step)
            d = _clip(0.5 * (L_B - L_D), d_prev - step, d_prev + step)
            L_B, L_D = c + d, c - d
        self.last = (L_B, L_D)
        return L_B, L_D, {"delta_l": dl, "delta_l_star": dls, "mu": mu, "L3": L3}


def _four_floats(x) -> list[float]:
    """The four values of the lines A, B, C, D as Python floats (``x`` a (4,) array or sequence)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1:
        return x.tolist()
    return np.asarray(x, dtype=float).reshape(-1).tolist()


def _clip(x: float, lo: float, hi: float) -> float:
    """``float(np.clip(x, lo, hi))`` of floats, NumPy's rules included: NaN propagates from ``x`` and from either
    bound, ``x`` equal to ``lo`` gives ``x`` and equal to ``hi`` gives ``x`` (the sign of a zero kept as NumPy keeps
    it on 0-d values; tests/dynamics/test_control.py compares the two)."""
    m = x if (x != x or x >= lo) else lo
    if m != m:
        return m
    return hi if (hi != hi or hi < m) else m


def actuate(L_B, L_D, L_B_prev, L_D_prev, cfg: ControlConfig):
    """The rest lengths ``(L_B, L_D)`` the KCU reaches in one controller period from ``(L_B_prev, L_D_prev)``
    (floats or arrays): its steering motor moves half the difference ``(L_B - L_D) / 2`` and its depower motor the
    mean ``(L_B + L_D) / 2``, each at most at ``control.line_speed_max_mps``, so a saturated steering command leaves
    the force loop's common change its own speed. No limit (0, the paper's Eq. 16-17 set the rest lengths
    directly): as commanded."""
    if cfg.line_speed_max_mps <= 0.0:
        return L_B, L_D
    step = cfg.line_speed_max_mps * cfg.control_dt_s
    c_prev, d_prev = 0.5 * (np.asarray(L_B_prev) + L_D_prev), 0.5 * (np.asarray(L_B_prev) - L_D_prev)
    c = np.clip(0.5 * (np.asarray(L_B) + L_D), c_prev - step, c_prev + step)
    d = np.clip(0.5 * (np.asarray(L_B) - L_D), d_prev - step, d_prev + step)
    return c + d, c - d


def force_integral(integral, error, cfg: ControlConfig):
    """The force loop's integral ``I + (mu* - mu) dt_c`` over one controller period, clamped so that
    ``|K3i I| <= control.force_integral_max_m`` (anti-windup); works on floats and arrays (batched env)."""
    if cfg.k3i_per_s <= 0.0:
        return integral * 0.0
    lim = cfg.force_integral_max_m / cfg.k3i_per_s
    return np.clip(integral + error * cfg.control_dt_s, -lim, lim)
