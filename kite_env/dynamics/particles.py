"""Particle-system model of wing masses, bridle lines, kite control unit and tether (Bosch et al., Sect. II.C, Fig. 5).

Five point masses in the wind frame W (:mod:`kite_env.frames`), rows ``A, B, C, D, KCU`` of the state arrays:

* ``m_A = m_C`` (leading edge) and ``m_B = m_D`` (trailing edge) carry the wing mass (70 % at the LE), ``m_KCU``
  the kite control unit (Table 1).
* Bridle lines A-KCU ... D-KCU: linear spring-dampers, Eq. (10), ``F_c = k_c (l - L) + c_c dl/dt`` along the line,
  pulling only (a line cannot push: ``F_c >= 0``). Power-line rest lengths ``L_A = L_C`` fixed, steering-line rest
  lengths ``L_B``, ``L_D`` set by the controllers.
* Line drag, Eq. (11): ``F_D,c = 1/2 rho C_D l d_c v_a,n^2`` along the normal component ``v_a,n`` of the line's
  apparent wind (mean of its end velocities minus the wind at its midpoint); half to each end.
* Relative damping between the wing tips (Sect. II.C: "damping forces F_d between the wing tips ... relative damping
  coefficients beta"): a dashpot along each pair A-C, B-D, A-D, B-C, ``c_ij = 2 beta_ij sqrt(k_ij mu_ij)`` with the
  reduced mass ``mu_ij`` and the stiffness ``k_ij`` of the wing between the two points, measured on the FE wing
  ("derived from numerical experiments", paper) by :func:`kite_env.dynamics.simulator.tip_stiffness`.
* Gravity on all masses (``-z_w``) and the wing forces ``F_k = -F_b`` on A-D (from the aeroelastic wing).
* Constraints (distance, paper Sect. II.C): tether ``|r_KCU| = l_t`` (ground station at the origin) and the stiff
  tip beams ``|r_A - r_B| = const``, ``|r_C - r_D| = const``: 15 coordinates - 3 constraints = 12 DOF (as the
  paper). Lagrange multipliers with Baumgarte stabilisation in the accelerations, Eq. (12-13) with
  ``M y'' = f + G^T lambda``, and a projection of positions and velocities onto the constraints after every step
  (drift reported by :meth:`ParticleSystem.constraint_violation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kite_env.config import DynamicsConfig
from kite_env.dynamics.lines import line_drag, tether_drag
from kite_env.frames import kite_frame

A, B, C, D, KCU = range(5)
#: bridle lines (wing point, KCU)
LINES = ((A, KCU), (B, KCU), (C, KCU), (D, KCU))
#: damped pairs between the wing points
DAMPED_PAIRS = ((A, C), (B, D), (A, D), (B, C))


@dataclass
class ParticleState:
    """Positions and velocities of A, B, C, D, KCU in W: ``r``, ``v`` (5, 3) [m], [m/s]."""

    r: np.ndarray
    v: np.ndarray

    def copy(self) -> ParticleState:
        return ParticleState(self.r.copy(), self.v.copy())


def _dist_rows(r: np.ndarray, v: np.ndarray, i: np.ndarray, j: np.ndarray):
    d = r[i] - r[j]
    l = np.sqrt(np.einsum("ij,ij->i", d, d))
    e = d / l[:, None]
    ldot = np.einsum("ij,ij->i", e, v[i] - v[j])
    return d, l, e, ldot


class ParticleSystem:
    """Forces, constrained accelerations and constraint projection of the five-mass system.

    Parameters
    ----------
    cfg : DynamicsConfig
    tip_lengths : (2,) float [m]
        Constrained distances A-B and C-D (the wing's tip beams).
    pair_stiffness : (4,) float [N/m]
        Wing stiffness ``k_ij`` between the damped pairs ``DAMPED_PAIRS``.
    rho : float [kg/m^3]
    """

    def __init__(self, cfg: DynamicsConfig, tip_lengths, pair_stiffness, rho: float = 1.225):
        self.cfg = cfg
        self.m = np.array([cfg.mass_le_kg, cfg.mass_te_kg, cfg.mass_le_kg, cfg.mass_te_kg, cfg.mass_kcu_kg])
        self.tip_lengths = np.asarray(tip_lengths, dtype=float)
        self.rho = float(rho)
        beta = np.array([cfg.beta_ac, cfg.beta_bd, cfg.beta_diag, cfg.beta_diag])
        pi_, pj = np.array(DAMPED_PAIRS).T
        mu = self.m[pi_] * self.m[pj] / (self.m[pi_] + self.m[pj])
        self.pair_damping = 2.0 * beta * np.sqrt(np.maximum(np.asarray(pair_stiffness, float), 0.0) * mu)  # [N s/m]
        self._li, self._lj = np.array(LINES).T
        self._pi, self._pj = pi_, pj
        self.rest = np.array([cfg.power_line_length_m, cfg.power_line_length_m, cfg.power_line_length_m,
                              cfg.power_line_length_m])  # L_A, L_B, L_C, L_D; L_B, L_D set by set_steering()
        # the wing's mass matrix on A-D in frame K (set_wing_mass); None: the point masses m_A ... m_D
        self.wing_mass_K: np.ndarray | None = None
        self.wing_minv_K = np.zeros((12, 12))
        # tether length l_t and its rate (the winch, FlightSimulator): the constraint |r_KCU| = l_t at the time of
        # the call; the paper's constant tether: l_t = tether_length_m, rate 0
        self.tether_length = float(cfg.tether_length_m)
        self.reel_speed = 0.0

    def set_wing_mass(self, M_K: np.ndarray | None) -> None:
        """Carry the wing's mass on A-D as the (12, 12) symmetric positive definite matrix ``M_K`` [kg] in frame K
        (A, B, C, D x, y, z; :func:`kite_env.dynamics.wing_mass.condensed_wing_mass`) instead of the point masses
        ``m_A ... m_D``; None restores the point masses. The point masses still weight the constraint projection
        and the tip dampers' reduced masses."""
        if M_K is None:
            self.wing_mass_K = None
            self.wing_minv_K = np.zeros((12, 12))
            return
        M_K = np.asarray(M_K, dtype=float)
        if M_K.shape != (12, 12) or not np.allclose(M_K, M_K.T) or np.linalg.eigvalsh(M_K).min() <= 0.0:
            raise ValueError("the wing mass matrix must be a symmetric positive definite (12, 12) array")
        self.wing_mass_K = M_K
        self.wing_minv_K = np.linalg.inv(M_K)

    def set_steering(self, L_B: float, L_D: float) -> None:
        """Rest lengths of the right (B) and left (D) steering lines [m]."""
        if not (np.isfinite(L_B) and np.isfinite(L_D) and L_B > 0 and L_D > 0):
            raise ValueError(f"steering-line rest lengths must be positive and finite, got {L_B!r}, {L_D!r}")
        self.rest[1], self.rest[3] = L_B, L_D

    def kernel_parameters(self) -> tuple:
        """Parameters of the compiled right-hand side :func:`kite_env.dynamics.kernels.particle_accelerations`, in
        its argument order after ``K_b``: ``m (5,), rest (4,), k_c, c_c, rho, line_cd, line_diameter,
        tether_diameter, tether_length, reel_speed, tip_lengths (2,), pair_damping (4,), gravity, alpha,
        minv_K (12, 12), wing_inertia`` (SI units; the tether length and its rate as now set)."""
        cfg = self.cfg
        return (self.m, self.rest, float(cfg.line_stiffness_N_per_m), float(cfg.line_damping_Ns_per_m), self.rho,
                float(cfg.line_cd), float(cfg.line_diameter_m), float(cfg.tether_diameter_m),
                self.tether_length, self.reel_speed, self.tip_lengths, self.pair_damping, float(cfg.gravity_mps2),
                float(cfg.baumgarte_1_per_s), self.wing_minv_K, self.wing_mass_K is not None)

    # ------------------------------------------------------------------ forces
    def line_forces(self, r: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bridle-line tensions ``F_c`` (4,) [N] (Eq. 10, >= 0) and current lengths (4,) [m]."""
        _, l, _, ldot = _dist_rows(r, v, self._li, self._lj)
        T = self.cfg.line_stiffness_N_per_m * (l - self.rest) + self.cfg.line_damping_Ns_per_m * ldot
        return np.maximum(T, 0.0), l

    def forces(self, r: np.ndarray, v: np.ndarray, wind: np.ndarray, f_wing: np.ndarray) -> tuple[np.ndarray, dict]:
        """Applied forces on the five masses (5, 3) [N] (without constraint forces).

        Parameters
        ----------
        r, v : (5, 3) positions and velocities in W.
        wind : (5, 3) wind velocity at the masses [m/s].
        f_wing : (4, 3) wing forces F_k = -F_b on A-D in W [N].
        """
        cfg = self.cfg
        f = np.zeros((5, 3))
        f[:, 2] -= self.m * cfg.gravity_mps2
        if self.wing_mass_K is not None:
            f[:4, 2] = 0.0  # gravity on the wing mass: an acceleration in accelerations()
        f[:4] += f_wing
        # bridle lines, Eq. (10): the tension pulls the wing point towards the KCU and the KCU towards the wing
        d, l, e, ldot = _dist_rows(r, v, self._li, self._lj)
        T = np.maximum(cfg.line_stiffness_N_per_m * (l - self.rest) + cfg.line_damping_Ns_per_m * ldot, 0.0)
        f[:4] -= T[:, None] * e
        f[KCU] += (T[:, None] * e).sum(axis=0)
        # line drag, Eq. (11): normal component of the apparent wind of each line, half to each end
        va = 0.5 * (v[self._li] + v[self._lj]) - 0.5 * (wind[self._li] + wind[self._lj])
        fd = line_drag(-0.5 * self.rho * cfg.line_cd * cfg.line_diameter_m, va, e, l)
        f[:4] += 0.5 * fd
        f[KCU] += 0.5 * fd.sum(axis=0)
        if cfg.tether_diameter_m > 0.0:
            f[KCU] += tether_drag(-0.5 * self.rho * cfg.line_cd * cfg.tether_diameter_m, r[KCU], v[KCU], wind[KCU])
        # relative damping between the wing points (dashpots along the pairs)
        _, _, ep, pdot = _dist_rows(r, v, self._pi, self._pj)
        fp = (self.pair_damping * pdot)[:, None] * ep
        np.add.at(f, self._pi, -fp)
        np.add.at(f, self._pj, fp)
        return f, {"line_tension": T, "line_length": l}

    # ------------------------------------------------------------------ constraints
    def _constraints(self, r: np.ndarray, v: np.ndarray):
        """Constraint values g (3,), Jacobian G (3, 15) and the velocity term dG/dt v (3,) for g = 1/2 (|d|^2 - L^2)."""
        g = np.empty(3)
        G = np.zeros((3, 15))
        gdot_v = np.empty(3)
        rk = r[KCU]
        g[0] = 0.5 * (rk @ rk - self.tether_length**2)
        G[0, 3 * KCU:3 * KCU + 3] = rk
        gdot_v[0] = v[KCU] @ v[KCU] - self.reel_speed**2  # reeling tether: d2g/dt2 = G a + |v|^2 - l_t'^2
        for c, (i, j), L in ((1, (A, B), self.tip_lengths[0]), (2, (C, D), self.tip_lengths[1])):
            d = r[i] - r[j]
            dv = v[i] - v[j]
            g[c] = 0.5 * (d @ d - L * L)
            G[c, 3 * i:3 * i + 3] = d
            G[c, 3 * j:3 * j + 3] = -d
            gdot_v[c] = dv @ dv
        return g, G, gdot_v

    def accelerations(self, r: np.ndarray, v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Constrained accelerations (5, 3) and multipliers (3,): ``M a = f + G^T lambda`` (Eq. 12-13) with
        ``G a = -dG/dt v - 2 alpha G v - alpha^2 g`` (Baumgarte)."""
        g, G, gdot_v = self._constraints(r, v)
        al = self.cfg.baumgarte_1_per_s
        Minv = np.diag(np.repeat(1.0 / self.m, 3))
        a_free = Minv @ f.ravel()
        if self.wing_mass_K is not None:
            # A-D: M_W^-1 = blkdiag(R) M_K^-1 blkdiag(R)^T; gravity on the whole wing mass as -g e_z (the condensed
            # mass reproduces rigid translations, so the generalized weight is M g)
            _, R = kite_frame(r[A], r[B], r[C], r[D])
            Rb = np.kron(np.eye(4), R)
            Minv[:12, :12] = Rb @ self.wing_minv_K @ Rb.T
            a_free = Minv @ f.ravel()
            a_free[2:12:3] -= self.cfg.gravity_mps2
        Gv = G @ v.ravel()
        Gv[0] -= self.tether_length * self.reel_speed  # dg/dt of the reeling tether
        rhs = -gdot_v - 2.0 * al * Gv - al * al * g - G @ a_free
        S = G @ Minv @ G.T
        lam = np.linalg.solve(S, rhs)
        a = a_free + Minv @ (G.T @ lam)
        return a.reshape(5, 3), lam

    def project(self, r: np.ndarray, v: np.ndarray, iters: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Mass-weighted projection of positions, then velocities, onto the constraints (drift removal)."""
        minv = np.repeat(1.0 / self.m, 3)
        r = r.copy()
        for _ in range(iters):
            g, G, _ = self._constraints(r, v)
            S = (G * minv) @ G.T
            r = (r.ravel() - minv * (G.T @ np.linalg.solve(S, g))).reshape(5, 3)
        _, G, _ = self._constraints(r, v)
        S = (G * minv) @ G.T
        Gv = G @ v.ravel()
        Gv[0] -= self.tether_length * self.reel_speed  # radial KCU speed = reel speed
        v = (v.ravel() - minv * (G.T @ np.linalg.solve(S, Gv))).reshape(5, 3)
        return r, v

    def constraint_violation(self, r: np.ndarray) -> np.ndarray:
        """Length errors [m] of the tether, A-B and C-D constraints."""
        return np.array([np.linalg.norm(r[KCU]) - self.tether_length,
                         np.linalg.norm(r[A] - r[B]) - self.tip_lengths[0],
                         np.linalg.norm(r[C] - r[D]) - self.tip_lengths[1]])
