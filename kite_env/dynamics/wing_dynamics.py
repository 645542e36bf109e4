"""The wing with inertia (``structure.dynamic``): the FE wing integrated in time with its own mass.

The paper's wing is quasi-static: its 10 kg sit in four particles A-D, and the FE wing is solved for equilibrium at
the bridle points the particles prescribe (Sect. II.D). Such a wing has no state to carry it through an event where
no nearby equilibrium exists (a luffing or folding canopy): the step fails (docs/validation.md, "The overloaded wing on
the constant tether"). Here
the wing has mass and moves:

* **Mass.** The lumped nodal masses of :func:`kite_env.dynamics.wing_mass.nodal_wing_mass` (Table 1's total, 70 %
  on the LE tube), of which ``dynamics.wing_point_mass_share`` sits as Table 1's point masses on A-D (the tips'
  inertia: spread by area alone, B and D get 1.7 g and the released tip diverges within 0.2 s of the start;
  docs/model.md, "The wing with inertia"), on the translations. The rotations are massless (quasi-static) by default;
  ``structure.rotary_inertia_factor`` > 0 gives each node an isotropic rotary inertia, the factor times
  ``m (a^2 + b^2) / 24`` of its tributary rectangle (:func:`kite_env.dynamics.wing_mass.nodal_rotary_inertia`),
  integrated with the translations' Newmark rule on the step's spatial rotation vector. With massless rotations
  the step's tangent keeps the static rotational stiffness, near-singular (the canopy's drilling and bending,
  3e-4 N m/rad) and indefinite in a fold, at any step size (docs/environment.md, "Random steering").
  A-D are wing nodes: the partition moves to the bridle lines, the KCU and the tether stay in the particle model.
* **Added mass** of the air moved by the canopy normal to its chord: the 2-D flat plate's ``rho pi c^2 / 4`` per
  unit span (Newman, *Marine Hydrodynamics*, MIT Press 1977, Sect. 4.13, table of added masses), with
  the low-aspect-ratio factor ``k_C = AR / (1 + AR)`` of Lissaman & Brown's parafoil model ("Apparent mass effects
  on parafoil dynamics", AIAA-93-1236, 1993), scaled by ``structure.added_mass_factor`` (0: none). Each section's
  added mass acts along its normal ``e_z`` and is lumped on its nodes by their chordwise tributary length. Its
  force is ``M_a a`` plus the part of Theodorsen's non-circulatory load that ``M_a a`` misses
  (:meth:`WingDynamics.normal_rate_force`).
* **Aerodynamics of a moving wing** (:class:`StepLoad`): the loads of Eq. 2-9 at the iterate's shape with the
  inflow of the wing's rigid *translation* (the mass-weighted fit of its velocities at the step's start), plus the
  damping of each section's deviation from it, rotation and deformation together, through the consistent section damping
  (docs/model.md, "Aerodynamic damping"; ``W^T C W`` with the velocity sampled at the 3/4-chord point, Pistolesi's
  point as
  ``aero.rotation_point``; dissipative by construction): Eq. (2)'s ``v_k + omega x r + u`` taken from the wing's
  own nodes.
* **Structural damping**: stiffness-proportional (Rayleigh) ``beta K_T(x_n)`` on the nodal translations, acting on
  the motion relative to the rigid-body motion, ``beta = structure.rayleigh_beta_s`` (by default 2 % of critical,
  the level of the relative damping coefficients the paper gives its wing, Table 1, at 4 Hz, the wing's lowest elastic
  mode in flight, and more above). ``K_T`` is the tangent
  of the wing's shape at most ``structure.rayleigh_tangent_period_s`` (20 ms) before, turned with the frame.
* **Bridle lines** of Eq. (10) (spring-dampers, pulling only) from A-D to the KCU, whose position at the end of the
  step is given (the staggered partition: the KCU's explicit step first, then the wing's implicit step); line drag
  (Eq. 11), half to the wing end. Gravity on the nodal masses.
* **Time integration:** generalized-alpha (Chung & Hulbert, "A time integration algorithm for structural dynamics
  with improved numerical dissipation: the generalized-alpha method", J. Appl. Mech. 60, 371, 1993) with
  ``alpha_m = (2 rho - 1) / (rho + 1)``, ``alpha_f = rho / (rho + 1)``, ``gamma = 1/2 - alpha_m + alpha_f``,
  ``beta = (1 - alpha_m + alpha_f)^2 / 4`` from the spectral radius ``rho = structure.rho_inf`` (second order, 1 =
  no dissipation). Nonlinear forces are averaged (Erlicher, Bonaventura & Bursi, Comput. Mech. 28, 83, 2002):
  ``(1 - alpha_f) r(x_n+1) + alpha_f r(x_n) + M a_n+1-alpha_m = 0`` with ``r = f_int - f_ext``. The Newton solve is
  the existing one (:class:`kite_env.structure.solver.StaticSolver`, banded LU on the same pattern) with a load
  object that returns ``f_ext - alpha_f/(1-alpha_f) r_n - M a_n+1-alpha_m / (1-alpha_f)`` and the tangent
  ``-d f_ext/dx - gamma/(beta dt) d f_ext/dv + (1-alpha_m)/((1-alpha_f) beta dt^2) M``.
* **Frame.** Each step is made in the kite frame K of its start (from A-D), held fixed over the step (an inertial
  frame for that step: no frame forces); between steps the state is re-expressed in the next step's frame, so the
  wing stays close to its design pose in K (the section frames orient themselves by ``y_k``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from kite_env.aero.kernels import section_loads_fields, section_normal_rate_forces
from kite_env.aero.loads import load_jacobian, section_damping, section_loads
from kite_env.aero.sections import section_geometry, skew, spanwise_directions
from kite_env.dynamics.kernels import wing_bridle_lines
from kite_env.dynamics.lines import LINE_SMOOTHING_N, line_drag, line_tension
from kite_env.dynamics.wing_mass import nodal_rotary_inertia, nodal_wing_mass
from kite_env.frames import cross
from kite_env.fsi import AeroelasticWing, FlightState, WingConvergenceError
from kite_env.geometry.mesh import BEAM_TIP
from kite_env.structure.assembly_kernels import csc_gather_matvec
from kite_env.structure.beam import BeamSet
from kite_env.structure.rotation_kernels import relative_rotation_vectors
from kite_env.structure.rotations import expm, logm
from kite_env.structure.shell_membrane import membrane_discrete_gradient, membrane_internal
from kite_env.structure.solver import ConvergenceError, NodalState, StaticSolver

_UNIT_X = np.array([1.0, 0.0, 0.0])

@dataclass(frozen=True)
class AlphaParameters:
    """Generalized-alpha parameters (Chung & Hulbert 1993, Eq. 25 and 17) from the spectral radius at infinite
    frequency ``rho_inf`` in [0, 1]."""

    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def from_rho_inf(cls, rho_inf: float) -> AlphaParameters:
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf must lie in [0, 1], got {rho_inf}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        return cls(am, af, 0.5 - am + af, 0.25 * (1.0 - am + af) ** 2)


def added_mass(mesh, geometry, rho: float, factor: float, aspect_ratio: float) -> np.ndarray:
    """Added mass of every section (n_sec,) [kg]: ``factor k_C rho pi c^2 w / 4`` with ``k_C = AR / (1 + AR)``
    (module docstring)."""
    k_c = aspect_ratio / (1.0 + aspect_ratio)
    return factor * k_c * rho * np.pi * geometry.chord**2 * np.asarray(mesh.section_width, float) / 4.0


class StepLoad:
    """External and inertial forces of one generalized-alpha step as a function of the Newton iterate (the load
    protocol of :meth:`StaticSolver.solve`). Public for the linearisations of :mod:`kite_env.analysis.turn_rate`,
    which build it at chosen velocity states.

    Section loads (the quasi-steady split of the consistent section damping, now with the wing's own motion): the
    loads of Eq. (2-9) at the iterate's shape with the inflow of the wing's rigid translation ``u_ref`` (the
    mass-weighted rigid fit of the wing's velocities at the start of the step, held over it), plus the damping
    forces of each section's deviation ``u_i = sum_j W_ij v_ij - u_ref`` from it, ``f_ij = -W_ij C_i u_i``, with the
    section damping ``C_i = -dF_i/du`` of :func:`kite_env.aero.loads.section_damping` (symmetric part positive
    semi-definite). The velocity is sampled and the force returned with the same weights ``W``
    (:meth:`WingDynamics.section_weights`), so the nodal damping matrix ``W^T C W`` dissipates energy for every motion
    of the nodes. Two alternatives were linearised or flown and rejected (docs/model.md, "The wing with inertia"): the
    inflow of the 3/4-chord point's own velocity with the load change spread by the moment law of Eq. 9 lets a
    single trailing-edge node drive itself (a TE flutter at 20-80 Hz growing at 10-26 1/s); the rigid rotation in
    the reference inflow (its load change spread by the moment law, one step behind) drives the 3 Hz yaw/twist mode.
    """

    def __init__(self, dyn: WingDynamics, dt: float, r_kcu, v_kcu, rest, g_K, v_wind, at: NodalState | None = None):
        self.dyn, self.dt = dyn, dt
        p = dyn.alpha
        self.c_a = 1.0 / (p.beta * dt * dt)  # d a / d x
        self.c_v = p.gamma / (p.beta * dt)  # d v / d x
        self.x_pred = dyn.state.x + dt * dyn.v + dt * dt * (0.5 - p.beta) * dyn.a
        self.v_pred = dyn.v + dt * (1.0 - p.gamma) * dyn.a
        # rotations (rotary inertia): the spatial rotation vector th of each node over the step, R = exp(th) R_n,
        # in the same Newmark form as the translations (small rotations per step)
        self.R_n = dyn.state.Rn
        self.th_pred = dt * dyn.w + dt * dt * (0.5 - p.beta) * dyn.aw
        self.w_pred = dyn.w + dt * (1.0 - p.gamma) * dyn.aw
        self.r_kcu, self.v_kcu = np.asarray(r_kcu, float), np.asarray(v_kcu, float)
        self.rest, self.g_K = np.asarray(rest, float), np.asarray(g_K, float)
        self.v_wind = np.asarray(v_wind, float)
        self.tangent_key = ("dynamic", round(np.log(dt) / np.log(1.25)))
        self.n_tangent = 0
        self.loads = self.collapsed = None
        self.f_phys = self.f_eff = None
        # the added mass's normal-rate force (WingDynamics.normal_rate_force) at each iterate: (normals at the step
        # start, the sections' added masses, the step), or None
        self.normal_rate = None
        self.line = None
        # the canopy's membrane forces of the step start (energy-consistent membrane forces, dyn.membrane_forces)
        self.f_m0 = dyn.membrane_force(dyn.state.x) if dyn.energy_consistent_membrane else None
        # held over the step: the sampling weights, the rigid-body inflow, the section damping and the structural
        # damping's tangent. They are evaluated where the step ends, not where it starts: at ``at``, the Newton start
        # (the last change of shape repeated, second-order close to the step's end), and with the rigid translation
        # of the Newmark estimate ``v_n + dt a_n`` of the end velocities. Held at the step's start, each of them lags
        # the forces of the step's end (where generalized-alpha takes them) by one step, a first-order error: the KCU
        # of the 10 s baseline then drifted 39 cm along the path at dt = 10 ms against 5 ms (2.5 ms: 19.5 cm), the
        # mean traction +0.34 % (-0.27 %); with the end-of-step evaluation a few centimetres and below 0.1 %
        # (docs/validation.md, "Time-step convergence")
        wing, mesh = dyn.wing, dyn.wing.mesh
        at = dyn.state if at is None else at
        x_sec0 = at.x[mesh.sections]
        self.W = dyn.section_weights(x_sec0)
        if dyn.hold_bridle:
            # held at A-D, the wing has no rigid motion: the reference is the support's (the tunnel's) frame, and the
            # deviation damping acts on all of the deformation velocity. The flight's reference below, the rigid fit
            # of the nodes' velocities, would take a part of the deformation (the trailing edge's motion) for a rigid
            # motion and feed it back into every section's inflow: a held wing with half its structural mass and no
            # added mass grew unstable at 5 ms with it, the default one from 44 m/s (docs/validation.md, "Against the
            # static wing")
            V, w = np.zeros(3), np.zeros(3)
        else:
            V, w = dyn.rigid_velocity()
            if at is not dyn.state:
                V = V + dt * dyn.rigid_velocity(dyn.a)[0]  # (the rigid fit is linear in the velocities)
        # the reference inflow is the wing's rigid translation only: its rotation (yaw, roll, pitch rates) enters,
        # with the deformation, through the dissipative deviation damping. Taken into the reference (each
        # section's load at the inflow of V + omega x r_p, held over the step, its change spread by the moment law
        # of Eq. 9), it drives the 3 Hz yaw/twist mode: the held 0.3 m input's yaw-rate oscillation grew from
        # 0.66 to 1.22 rad/s in 0.5 s and the wing folded at 1.5 s; with it here the oscillation decays like the
        # quasi-static wing's (docs/model.md, "The wing with inertia")
        self.u_ref = V
        self.inflow = self.v_wind - V  # "wind" of section_loads with v_kite = omega = 0
        self.C = section_damping(x_sec0, mesh.section_tube_d, mesh.section_width, np.zeros(3), np.zeros(3),
                                 self.inflow, wing.cfg.aero.rho_kg_m3, **wing.aero_options())
        # structural (Rayleigh) damping beta K_T(x) on the translations, of the motion relative to the rigid one; its
        # tangent is the structure's at the first iterate of a step, ``at`` (the Newton start), assembled in the
        # first call of force() and handed to the solver for that iterate (:meth:`assembled`), not assembled twice;
        # then held over the next steps of structure.rayleigh_tangent_period_s
        self.beta_K = float(wing.cfg.structure.rayleigh_beta_s)
        self.K0 = None  # the structure's tangent data K_T at the Newton start (beta K_T on the translations)
        self.Kb_at = None  # the tip rods' element tangents where K0 was assembled (in K0)
        self._Kb_state = None  # the iterate of Kb_at (this step's Newton start when assembled here)
        self._pre = None  # (iterate, f_int, tangent data) assembled by force() for the solver
        self.K0_turn = None  # the frame's turn since K0 was assembled (3, 3), None: assembled in this frame
        self.K0_fresh = False  # assembled in this step
        held = dyn.rayleigh_held
        if self.beta_K > 0.0 and held is not None and held[2] + dt < dyn.rayleigh_period * (1.0 - 1e-9):
            # the tangent of a step that ended less than structure.rayleigh_tangent_period_s before this one will:
            # held, its assembly at this Newton start is skipped. It is the tangent of the wing's shape then, turned
            # with the frame since (Q K Q^T on each node pair's block): in the frame of its assembly it would damp
            # the deformation of a shape turned by the frame's rotation (about 1 deg in 20 ms of a turn). The
            # Newton tangent takes it turned as well (operators; the tip rods' correction of a kept factorisation,
            # tangent_change, their turned share): unturned, the load's tangent was 11 % off along the Newton
            # direction in the 10 m/s collapse (the frame turning at 15 rad/s) and a 5 ms step of the baseline made
            # 0.08 more Newton iterations (docs/performance.md, "The damping tangent held over 20 ms")
            self.K0, self.Kb_at, _, Q = held
            self.K0_turn = None if np.array_equal(Q, np.eye(3)) else Q
        self.Kb_turned = self.Kb_at  # the tip rods' share as the force takes it (turned with K0_turn)
        if self.K0_turn is not None and self.Kb_at is not None:
            Q12 = np.kron(np.eye(4), self.K0_turn)  # (each of the rods' two nodes: a translation and a rotation)
            self.Kb_turned = Q12 @ self.Kb_at @ Q12.T
        if self.beta_K > 0.0:
            self.v_rigid = V[None, :] + dyn.state.x @ skew(w).T  # V + w x x

    def kinematics(self, st: NodalState):
        a = (st.x - self.x_pred) * self.c_a
        return a, self.v_pred + self.dt * self.dyn.alpha.gamma * a

    def rotation_kinematics(self, st: NodalState):
        """Angular accelerations and velocities (n_nodes, 3) [rad/s^2, rad/s] of the iterate's rotations."""
        if self.dyn.compiled:
            th = relative_rotation_vectors(st.Rn, self.R_n, np.empty((len(st.Rn), 3)))
        else:
            th = logm(np.einsum("nij,nkj->nik", st.Rn, self.R_n))
        aw = (th - self.th_pred) * self.c_a
        return aw, self.w_pred + self.dt * self.dyn.alpha.gamma * aw

    def section_deviation(self, v: np.ndarray) -> np.ndarray:
        """``u_i = sum_j W_ij v_ij - u_ref`` (n_sec, 3) [m/s]."""
        return np.einsum("ij,ijk->ik", self.W, v[self.dyn.wing.mesh.sections]) - self.u_ref

    def _lines(self, x, v):
        """The bridle lines (Eq. 10) at the iterate: ``e`` (4, 3) the unit vectors KCU -> A-D, ``l`` (4,) [m],
        tension ``T`` (4,) [N] and ``dT = dT/ds`` (:func:`kite_env.dynamics.lines.line_tension`), and the wing ends'
        half of their drag (Eq. 11) (4, 3) [N]."""
        dyn = self.dyn
        b = dyn.bridle
        if dyn.compiled:
            e, l, T, dT, drag = np.empty((4, 3)), np.empty(4), np.empty(4), np.empty(4), np.empty((4, 3))
            wing_bridle_lines(x[b], v[b], self.r_kcu, self.v_kcu, self.v_wind_mid, self.rest, dyn.k_c, dyn.c_c,
                              dyn.line_drag, LINE_SMOOTHING_N, e, l, T, dT, drag)
            return e, l, T, dT, drag
        d = x[b] - self.r_kcu
        l = np.linalg.norm(d, axis=1)
        e = d / l[:, None]
        ldot = np.einsum("ij,ij->i", e, v[b] - self.v_kcu)
        T, dT = line_tension(dyn.k_c * (l - self.rest) + dyn.c_c * ldot)
        drag = 0.5 * line_drag(dyn.line_drag, 0.5 * (v[b] + self.v_kcu) - self.v_wind_mid, e, l)
        return e, l, T, dT, drag

    def force(self, st: NodalState) -> np.ndarray:
        dyn, wing = self.dyn, self.dyn.wing
        mesh = wing.mesh
        a, v = self.kinematics(st)
        self.collapsed = wing.update_tube_stiffness(st)
        if self.beta_K > 0.0 and self.K0 is None:
            asm = wing.prescribed_assembly
            f_int, kd = asm.assemble_data(st.x, st.Rn, tangent=True)
            self._pre = (st, f_int, kd)
            self.K0 = kd  # (on the nodal translations alone in the force: WingDynamics.translation_product)
            self.K0_fresh = True
            if dyn.tip_rods is not None:
                self.Kb_at = self.Kb_turned = dyn.tip_tangents(st)
                self._Kb_state = st
        x_sec = st.x[mesh.sections]
        zero = np.zeros(3)
        self.loads = section_loads(x_sec, mesh.section_tube_d, mesh.section_width, zero, zero, self.inflow,
                                   wing.cfg.aero.rho_kg_m3, **wing.aero_options())
        # (the loads' own new array: the damping forces added in place)
        self.loads.nodal_forces[...] -= self.W[:, :, None] * np.einsum("ikl,il->ik", self.C,
                                                                        self.section_deviation(v))[:, None, :]
        f = wing.load_vector(self.loads)
        f6 = f.reshape(-1, 6)
        if self.K0 is not None:
            f6[:, :3] -= self.rayleigh_force(v - self.v_rigid)
        # bridle lines, Eq. (10), and their drag, Eq. (11) (half to the wing end)
        e, l, T, _, drag = self._lines(st.x, v)
        self.line = (T, l, e)
        f6[dyn.bridle, :3] -= T[:, None] * e
        f6[dyn.bridle, :3] += drag
        f6[:, :3] += dyn.m_node[:, None] * self.g_K[None, :]
        if self.normal_rate is not None:
            f6[:, :3] += dyn.normal_rate_force(self.normal_rate, st.x, v, self.v_wind)
        self.f_phys = f.copy()
        p = dyn.alpha
        a_m = (1.0 - p.alpha_m) * a + p.alpha_m * dyn.a
        f6[:, :3] -= np.einsum("nij,nj->ni", dyn.M_blocks, a_m) / (1.0 - p.alpha_f)
        if dyn.has_rotary_inertia:
            aw, _ = self.rotation_kinematics(st)
            aw_m = (1.0 - p.alpha_m) * aw + p.alpha_m * dyn.aw
            f6[:, 3:] -= dyn.J_node[:, None] * aw_m / (1.0 - p.alpha_f)
        f -= (p.alpha_f / (1.0 - p.alpha_f)) * dyn.r_prev
        if dyn.carry is not None:  # the last step's unbalanced residual, with its impulse over this step
            f += dyn.carry[0] * (dyn.carry[1] / self.dt)
        if self.f_m0 is not None:
            # the membrane's averaged force (1 - alpha_f) f_m(x_n+1) + alpha_f f_m(x_n) of the equation above becomes
            # the discrete gradient f_alg(x_n, x_n+1), whose work is the change of the stored energy
            f += dyn.membrane_force(st.x) + (p.alpha_f / (1.0 - p.alpha_f)) * self.f_m0 \
                    - dyn.membrane_force(st.x, x0=dyn.state.x) / (1.0 - p.alpha_f)
        self.f_eff = f
        return f

    def rayleigh_force(self, u: np.ndarray) -> np.ndarray:
        """The structural damping's force ``beta K_T u`` (n_nodes, 3) [N] on the nodal translations for the
        velocities ``u`` (n_nodes, 3) [m/s] relative to the rigid motion, with the step's tangent ``K0``, turned by
        ``K0_turn`` when held from an earlier frame (``Q K Q^T u``)."""
        Q = self.K0_turn
        if Q is None:
            return self.dyn.translation_product(self.K0, self.beta_K, u)
        return self.dyn.translation_product(self.K0, self.beta_K, u @ Q) @ Q.T

    def tangent_snapshot(self, st: NodalState):
        """The tip rods' element tangents at ``st``, where the solver factorises the step's tangent, and their share
        of the step's Rayleigh damping tangent ``K0`` as the factorisation holds it (turned with ``K0_turn``): what
        :meth:`tangent_change` compares with."""
        dyn = self.dyn
        if dyn.tip_rods is None:
            return None
        # (a factorisation at the Newton start: the tangents force() evaluated there)
        return (self.Kb_at if st is self._Kb_state else dyn.tip_tangents(st)), self.Kb_turned

    def tangent_change(self, st: NodalState, snapshot) -> tuple | None:
        """The change of the step's tangent on the tip rods' DOF since the factorisation of ``snapshot``
        (:meth:`tangent_snapshot`): their stiffness at the iterate, and their share of the Rayleigh damping ``c_v
        beta K_T`` of this step (``K0``, turned). Returns ``(dofs, dT)`` for :meth:`StaticSolver._block_correction`.

        The tip rods (glass fibre, the wing's stiffest members: ``EA / L`` about 1e7 N/m) turn with the tips'
        twist from step to step. A factorisation kept over a few steps (modified Newton) has their axial stiffness
        along the old direction, and the first Newton increment then contracts the residual by 0.02 (median)
        where a fresh tangent gives 1e-3; four fifths of the next residual are this change
        (docs/performance.md, "Newton's iterations"). The rods are cheap to evaluate and sit on 12 nodes."""
        if snapshot is None:
            return None
        dyn = self.dyn
        Kt0, Kt_at0 = snapshot
        D = dyn.tip_tangents(st) - Kt0
        if self.K0 is not None and Kt_at0 is not None and self.Kb_at is not None:
            D += (self.c_v * self.beta_K) * dyn.tip_tt * (self.Kb_turned - Kt_at0)
        k = dyn.tip_dofs.size
        return dyn.tip_dofs, np.bincount(dyn.tip_block_index, weights=D.ravel(), minlength=k * k).reshape(k, k)

    def assembled(self, st: NodalState):
        """``(f_int, tangent data)`` of the structure at ``st`` if :meth:`force` assembled them at that iterate (the
        step's first), else None (the load protocol of :meth:`StaticSolver.solve`)."""
        pre, self._pre = self._pre, None
        return pre[1:] if pre is not None and pre[0] is st else None

    @property
    def v_wind_mid(self):
        return self.v_wind if self.v_wind.ndim == 1 else self.v_wind.mean(axis=0)

    def tangent(self, st: NodalState) -> np.ndarray:
        """``-d f_eff / d x`` on the pattern: ``K + c_v C + c_m M`` (:meth:`operators`)."""
        p = self.dyn.alpha
        c_m = (1.0 - p.alpha_m) / ((1.0 - p.alpha_f) * p.beta * self.dt * self.dt)
        K, C, M = self.operators(st)
        self.n_tangent += 1
        if self.f_m0 is not None:
            K = K + self.dyn.membrane_tangent_correction(st.x, self.dyn.state.x)
        return K + self.c_v * C + c_m * M

    def operators(self, st: NodalState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pattern data of the linearised external forces at the iterate ``st``: stiffness ``K = -d f_ext / d x``
        (aerodynamic loads at the held inflow, bridle lines), damping ``C = -d f_ext / d v`` (the sections'
        ``W^T C_i W``, the line dampers) and mass ``M`` (nodal blocks with the added mass): the Newton tangent of a
        step, over which the reference inflow ``u_ref`` is held. They are not the free wing's linearised motion:
        between steps ``u_ref`` follows the wing's rigid translation, whose loads (forces and the moment of Eq. 9, not
        projected) replace the section damping's response to it; :func:`kite_env.analysis.turn_rate.tethered_wing_modes`
        linearises that (with ``C`` alone the rig's yaw mode is 2.93 Hz at 15.8 % of critical, with the translation's
        loads 3.59 Hz at 1.0 %, as the stepped rig; docs/steering.md, "The yaw rig")."""
        dyn, wing = self.dyn, self.dyn.wing
        mesh = wing.mesh
        asm = wing.prescribed_assembly
        _, v = self.kinematics(st)
        x_sec = st.x[mesh.sections]
        zero = np.zeros(3)
        _, J = load_jacobian(x_sec, mesh.section_tube_d, mesh.section_width, zero, zero, self.inflow,
                             wing.cfg.aero.rho_kg_m3, **wing.aero_options())
        n_sec, m, _ = x_sec.shape
        W = self.W
        Cn = W[:, :, None, None, None] * W[:, None, None, :, None] * self.C[:, None, :, None, :]  # (i, j, k, n, l)
        K = asm.block_data(-J)
        C = asm.block_data(Cn.reshape(n_sec, 3 * m, 3 * m))
        M = np.zeros(asm.nnz)
        used = dyn.used_nodes
        np.add.at(M, dyn.node_blocks[used].ravel(), dyn.M_blocks[used].ravel())
        if dyn.has_rotary_inertia:  # d th / d spin = I for the small rotations of a step
            M[dyn.rot_diag] += np.repeat(dyn.J_node[used], 3)
        e, l, T, dT, _ = self._lines(st.x, v)
        ee = e[:, :, None] * e[:, None, :]
        blk = dyn.node_blocks[dyn.bridle].ravel()
        np.add.at(K, blk, ((dT * dyn.k_c)[:, None, None] * ee + (T / l)[:, None, None] * (np.eye(3) - ee)).ravel())
        np.add.at(C, blk, ((dT * dyn.c_c)[:, None, None] * ee).ravel())
        if self.K0 is not None:
            C += self.beta_K * (self.K0 if self.K0_turn is None else dyn.turned_translations(self.K0, self.K0_turn)) \
                * dyn.tt_mask
        if self.normal_rate is not None:
            K_nr, C_nr = dyn.normal_rate_tangent(self.normal_rate, st.x, v, self.v_wind)
            K += asm.block_data(K_nr)
            C += asm.block_data(C_nr)
        return K, C, M


class WingDynamics:
    """Time integration of the FE wing with inertia (module docstring) in the frame of the current step.

    State: the wing's :class:`NodalState` ``state``, nodal velocities ``v`` and accelerations ``a`` (n_nodes, 3)
    [m/s, m/s^2] in the current frame, and the force residual ``r_prev = f_int - f_ext`` (n_dof,) of the last step
    (generalized-alpha averages it with the new one).
    """

    def __init__(self, wing: AeroelasticWing, hold_bridle: bool = False):
        self.wing = wing
        cfg = wing.cfg
        mesh = wing.mesh
        # a wing held at A-D (a wind tunnel's support; verification against the static wing): their translations
        # are prescribed where they are, and F_b is the support's force on the wing instead of the lines'
        self.hold_bridle = bool(hold_bridle)
        self.held_dofs = ((6 * np.asarray(mesh.bridle)[:, None] + np.arange(3)).ravel() if self.hold_bridle
                          else np.zeros(0, np.int64))
        self.alpha = AlphaParameters.from_rho_inf(cfg.structure.rho_inf)
        self.compiled = wing.beams.backend == "numba"  # the compiled kernels of the wing's elements are available
        self.bridle = np.asarray(mesh.bridle)
        # dynamics.wing_point_mass_share of Table 1's masses as the paper's point masses on A-D, the rest spread
        f = cfg.dynamics.wing_point_mass_share
        m_spread = (1.0 - f) * nodal_wing_mass(mesh, cfg.dynamics)
        self.m_node = m_spread.copy()
        self.m_node[self.bridle] += f * np.array([cfg.dynamics.mass_le_kg, cfg.dynamics.mass_te_kg,
                                                  cfg.dynamics.mass_le_kg, cfg.dynamics.mass_te_kg])
        d = cfg.dynamics
        self.k_c, self.c_c = float(d.line_stiffness_N_per_m), float(d.line_damping_Ns_per_m)
        self.line_drag = -0.5 * cfg.aero.rho_kg_m3 * d.line_cd * d.line_diameter_m
        asm = wing.prescribed_assembly
        self.solver = StaticSolver(asm, mode="modified", max_iter=cfg.fsi.max_newton_iter, contraction=0.5,
                                   nodal_rot_limit=True, error_estimate=True)
        n = mesh.n_nodes
        idx = asm.matrix(np.arange(1, asm.nnz + 1, dtype=float)).tocsr()
        rows = (6 * np.arange(n)[:, None, None] + np.arange(3)[None, :, None]) + np.zeros((1, 1, 3), np.int64)
        cols = (6 * np.arange(n)[:, None, None] + np.arange(3)[None, None, :]) + np.zeros((1, 3, 1), np.int64)
        self.node_blocks = np.asarray(idx[rows.ravel(), cols.ravel()]).ravel().astype(np.int64).reshape(n, 3, 3) - 1
        self.used_nodes = np.flatnonzero(asm.node_used)
        # rotary inertia of the nodes (structural mass without the point masses on A-D)
        self.J_node = cfg.structure.rotary_inertia_factor * nodal_rotary_inertia(mesh, m_spread)
        self.has_rotary_inertia = bool(np.any(self.J_node > 0.0))
        self.rot_diag = asm.diag_index[(6 * self.used_nodes[:, None] + np.arange(3, 6)[None, :]).ravel()]
        dof_r = np.repeat(np.arange(asm.n_dof), np.diff(asm.indptr))  # column of each pattern entry (CSC)
        sec = np.asarray(mesh.sections).ravel()
        self._sections_partition = np.unique(sec).size == sec.size
        self.tt_mask = ((asm.indices % 6 < 3) & (dof_r % 6 < 3)).astype(float)  # translation-translation entries
        # the translation-translation entries as a CSC matrix on the translations alone (translation_matrix)
        tt = np.flatnonzero(self.tt_mask)
        self._tt_entries = tt
        self._tt_indices = (3 * (asm.indices[tt] // 6) + asm.indices[tt] % 6).astype(np.int32)
        col_t = 3 * (dof_r[tt] // 6) + dof_r[tt] % 6
        self._tt_indptr = np.searchsorted(col_t, np.arange(3 * n + 1)).astype(np.int32)
        # the translation-translation entries as whole 3x3 node-pair blocks (n_blocks, 3, 3) (turned_translations)
        row_n, col_n = asm.indices[tt] // 6, dof_r[tt] // 6
        pair, block = np.unique(row_n.astype(np.int64) * n + col_n, return_inverse=True)
        self._tt_blocks = np.full((pair.size, 3, 3), -1, dtype=np.int64)
        self._tt_blocks[block, asm.indices[tt] % 6, dof_r[tt] % 6] = tt
        if np.any(self._tt_blocks < 0):
            raise RuntimeError("the wing's tangent pattern has a partial translation block")
        # the tip rods, a set of their own with the wing's properties: their tangents correct a kept factorisation
        # (StepLoad.tangent_change)
        tip = np.flatnonzero(np.asarray(mesh.beam_kind) == BEAM_TIP)
        self.tip_rods = None
        if tip.size:
            b = wing.beams
            self.tip_rods = BeamSet(b.conn[tip], mesh.nodes, np.asarray(mesh.beam_up)[tip], b.EA[tip], b.EI2[tip],
                                    b.EI3[tip], b.GJ[tip], backend=b.backend)
            nodes = np.unique(b.conn[tip])
            self.tip_dofs = (6 * nodes[:, None] + np.arange(6)).ravel()
            pos = np.full(wing.n_dof, -1, dtype=np.int64)
            pos[self.tip_dofs] = np.arange(self.tip_dofs.size)
            ed = pos[(6 * b.conn[tip][:, :, None] + np.arange(6)).reshape(-1, 12)]  # (n_tip, 12) block positions
            self.tip_block_index = (ed[:, :, None] * self.tip_dofs.size + ed[:, None, :]).ravel()
            tr = np.arange(12) % 6 < 3
            self.tip_tt = (tr[:, None] & tr[None, :]).astype(float)  # translation-translation entries (12, 12)
        if np.any(self.node_blocks[self.used_nodes] < 0):
            raise RuntimeError("the wing's tangent pattern lacks a nodal translation block")
        self.state: NodalState | None = None
        self.v = self.a = self.r_prev = None
        # (rho, dt) of the last step: the residual its Newton left (free DOF; structure.carry_residual) and its step
        self.carry: tuple | None = None
        self.carry_residual = cfg.structure.carry_residual
        # the Rayleigh damping's tangent held over steps: (tangent data, tip rods' tangents, the time from the end of
        # the step that assembled it to the current state [s], the frame's turn since then (3, 3)) or None
        self.rayleigh_held: tuple | None = None
        self.rayleigh_period = float(cfg.structure.rayleigh_tangent_period_s)
        self.w = self.aw = None  # nodal angular velocities and accelerations (n_nodes, 3), spatial, frame of the step
        self.M_blocks = None
        self._prev: tuple | None = None  # (state, dt) before the last step, in the current frame (predictor)
        self._rigid_fit: tuple | None = None  # (positions, mass, centre, mass-weighted offsets, inverse inertia)
        self.energy_consistent_membrane = cfg.structure.membrane_forces == "energy_consistent"
        if self.energy_consistent_membrane:  # scatter maps of the canopy's translations (membrane_force, ..._tangent_)
            sh = wing.shells
            self._shell_dofs = (6 * sh.conn[:, :, None] + np.arange(3)[None, None, :]).reshape(-1)
            shell_map = asm.set_maps[[i for i, es in enumerate(asm.sets) if es is sh][0]].reshape(-1, 18, 18)
            tr = (6 * np.arange(3)[:, None] + np.arange(3)[None, :]).ravel()  # translations of the element's 18 DOF
            self._shell_tt = shell_map[:, tr][:, :, tr]  # (n, 9, 9) pattern positions of the membrane's blocks

    def membrane_force(self, x: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """The canopy's membrane forces (n_dof,) [N] on the translations: at the positions ``x`` (n_nodes, 3) or,
        with ``x0``, the energy-consistent force of the step from ``x0`` to ``x``
        (:func:`kite_env.structure.shell_membrane.membrane_discrete_gradient`)."""
        sh = self.wing.shells
        if x0 is None:
            fe = membrane_internal(x[sh.conn], sh.G, sh.A0h, sh.E, sh.nu, sh.C, sh.eps_slack, sh.membrane_law)[1]
        else:
            fe = membrane_discrete_gradient(x0[sh.conn], x[sh.conn], sh.G, sh.A0h, sh.E, sh.nu, sh.C, sh.eps_slack,
                                            sh.membrane_law)[0]
        return np.bincount(self._shell_dofs, weights=fe.ravel(), minlength=self.wing.n_dof)

    def membrane_tangent_correction(self, x: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Pattern data of ``K_alg / (1 - alpha_f) - K_m(x)``: the derivative of the energy-consistent membrane
        force of the step (:meth:`membrane_force` with ``x0``) in the step's equation, less the membrane tangent at
        ``x`` that the structure's assembly already holds. Without it the modified Newton iteration stalls where
        the membrane's state (taut, wrinkled, slack) differs between the step's end and its midpoint."""
        sh = self.wing.shells
        K1 = membrane_internal(x[sh.conn], sh.G, sh.A0h, sh.E, sh.nu, sh.C, sh.eps_slack, sh.membrane_law)[2]
        Ka = membrane_discrete_gradient(x0[sh.conn], x[sh.conn], sh.G, sh.A0h, sh.E, sh.nu, sh.C, sh.eps_slack,
                                        sh.membrane_law, tangent=True)[3]
        dK = Ka / (1.0 - self.alpha.alpha_f) - K1
        return np.bincount(self._shell_tt.ravel(), weights=dK.ravel(), minlength=self.solver.asm.nnz)

    # ------------------------------------------------------------------ pieces
    def section_weights(self, x_sec: np.ndarray, point: str | None = None, tube_d: np.ndarray | None = None
                        ) -> np.ndarray:
        """Weights (n_sec, m) of the section nodes' velocities in the velocity of each section's rotation point
        (``aero.rotation_point``): the section's velocity field fitted, by least squares, as a linear function of
        the chordwise coordinate to all its nodes, evaluated at the 3/4-chord point (or at the LE node for
        ``"le_node"``). A rigid motion of the section is reproduced exactly; a motion of one node alone (a fluttering
        trailing edge) enters with its share of the fit, not with the whole interpolation weight. Taken from the
        chord line of the LE and TE nodes alone, the TE node's velocity weighs 0.7, and the TE node is driven by its
        own share of the section's lift change: a flutter of the trailing-edge nodes at 20-80 Hz growing at 26 1/s
        (linearised wing at the start of the baseline flight; docs/model.md, "The wing with inertia"). ``point``
        overrides ``aero.rotation_point``. As weights of a force on the section (``f_j = W_j F``) they place its
        resultant at that point, and its power is ``F . v_p``. ``tube_d`` (n_sec,) [m]: the sections' LE tube
        diameters (default: the mesh's, for its ``n_sec`` sections)."""
        d = self.wing.mesh.section_tube_d if tube_d is None else tube_d
        e = x_sec[:, -1] - x_sec[:, 0]
        cn = np.linalg.norm(e, axis=1)
        s = np.einsum("ijk,ik->ij", x_sec - x_sec[:, :1], e) / cn[:, None]  # (n_sec, m) along the chord [m]
        if (point or self.wing.cfg.aero.rotation_point) == "three_quarter_chord":
            s_p = 0.75 * (cn + 0.5 * d) - 0.5 * d
        else:
            s_p = np.zeros_like(cn)
        ds = s - s.mean(axis=1, keepdims=True)
        m = x_sec.shape[1]
        return 1.0 / m + ds * ((s_p - s.mean(axis=1)) / np.einsum("ij,ij->i", ds, ds))[:, None]

    def translation_matrix(self, data: np.ndarray):
        """The translation-translation part of pattern data (length ``nnz``) as a sparse matrix on the nodal
        translations alone (``3 n_nodes`` DOF, node-major)."""
        n = 3 * self.wing.mesh.n_nodes
        return sp.csc_matrix((data[self._tt_entries], self._tt_indices, self._tt_indptr), shape=(n, n))

    def turned_translations(self, data: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Pattern data (length ``nnz``) with every node pair's translation block ``B`` replaced by ``Q B Q^T``
        (the tangent of the shape turned by ``Q``; the other entries as they are)."""
        out = data.copy()
        out[self._tt_blocks] = Q @ data[self._tt_blocks] @ Q.T
        return out

    def translation_product(self, data: np.ndarray, scale: float, u: np.ndarray) -> np.ndarray:
        """``(scale T) u`` (n_nodes, 3) with ``T = translation_matrix(data)`` and ``u`` (n_nodes, 3): the same
        product, compiled, without building the matrix (the Rayleigh damping's force at every Newton iterate)."""
        u = np.ascontiguousarray(u, dtype=float).reshape(-1)
        if not self.compiled:
            return (self.translation_matrix(scale * data) @ u).reshape(-1, 3)
        out = np.empty_like(u)
        csc_gather_matvec(data, self._tt_entries, self._tt_indices, self._tt_indptr, float(scale), u, out)
        return out.reshape(-1, 3)

    def tip_tangents(self, st: NodalState) -> np.ndarray:
        """Element tangents (n_tip, 12, 12) of the tip rods at ``st``."""
        c = self.tip_rods.conn
        return self.tip_rods.internal(st.x[c], st.Rn[c], tangent=True)[1]

    def section_frames(self, x: np.ndarray):
        """The sections' geometry (frames ``e_x``, ``e_z``, ...) at the nodal positions ``x`` (n_nodes, 3)."""
        mesh = self.wing.mesh
        return self._frames_of(x[mesh.sections], mesh.section_tube_d, mesh.section_width)

    def _frames_of(self, x_sec, tube_d, width, spanwise=None):
        """The geometry of sections ``x_sec`` (n, m, 3) with LE tube diameters and widths (n,) [m]; ``spanwise``
        (n, 3): their LE-line tangents, held (default: from the LE nodes of ``x_sec``, neighbours in order)."""
        if self.compiled:  # the same frames from the compiled section kernel (its loads unused)
            return section_loads_fields(x_sec, tube_d, width, np.zeros(3), np.zeros(3), _UNIT_X, 1.0,
                                        spanwise=spanwise)[11]
        return section_geometry(x_sec, tube_d, spanwise)

    def update_mass(self, x: np.ndarray | None = None) -> None:
        """Nodal mass blocks (n_nodes, 3, 3) [kg] at the shape ``x`` (n_nodes, 3) [m] (default: the current one):
        structural mass plus the sections' added mass along their normals (held over a step). A step takes them at
        its predicted end: the normals turn with the wing, and the added mass (20 kg for the default wing, twice its
        own 10 kg) held at the step's start lags its inertial force by one step."""
        wing, mesh = self.wing, self.wing.mesh
        M = self.m_node[:, None, None] * np.eye(3)[None]
        f = wing.cfg.structure.added_mass_factor
        self.section_added_mass = None  # (n_sec,) [kg], for the normal-rate force
        if f > 0.0:
            x = self.state.x if x is None else x
            x_sec = x[mesh.sections]
            geom = self.section_frames(x)
            m_a = added_mass(mesh, geom, wing.cfg.aero.rho_kg_m3, f, wing.aspect_ratio)
            seg = np.linalg.norm(np.diff(x_sec, axis=1), axis=2)
            trib = np.zeros(mesh.sections.shape)
            trib[:, :-1] += 0.5 * seg
            trib[:, 1:] += 0.5 * seg
            share = m_a[:, None] * trib / trib.sum(axis=1, keepdims=True)  # (n_sec, m) [kg]
            self.section_added_mass = m_a
            nn = geom.e_z[:, :, None] * geom.e_z[:, None, :]
            add = (share[:, :, None, None] * nn[:, None]).reshape(-1, 3, 3)
            if self._sections_partition:  # (each node in one section: no repeated index)
                M[mesh.sections.ravel()] += add
            else:
                np.add.at(M, mesh.sections.ravel(), add)
        self.M_blocks = M

    def normal_rate_force(self, held, x: np.ndarray, v: np.ndarray, v_wind: np.ndarray) -> np.ndarray:
        """The part of Theodorsen's non-circulatory load that the mass blocks ``m_a n n^T`` miss,
        at the iterate ``x``, ``v`` (n_nodes, 3) [N].

        Theodorsen (1935, NACA Report 496) gives a plate's non-circulatory lift as ``pi rho b^2 (h'' + U alpha' -
        b a alpha'')``: the plunge and pitch accelerations act through the air's added mass at the plate's own
        acceleration (the mass blocks, by chordwise tributary length), and ``U alpha'``, the rate at which the plate
        turns its normal against the flow, acts at the three-quarter-chord point (its moment about the mid-chord is
        ``-pi rho b^3 U alpha' / 2``, a pitch damping). Here ``U alpha'`` is ``n' . v_rel`` for each section, with the
        normal's rate over the step from its start to the iterate and the air-relative velocity of the 3/4-chord
        point; the force ``-m_a (n' . v_rel) n`` is put on the section's nodes with the weights that place it at
        the 3/4-chord point (:meth:`section_weights`). In a steady turn or pull-up the section's normal velocity does
        not change: the two parts cancel in force (the mass blocks alone would pull each section with ``m_a`` times
        the turn's centripetal acceleration, as if the air turned with the wing) and leave the pitch-damping couple.
        ``held``: the normals at the step's start (n_sec, 3), the sections' added masses (n_sec,) [kg] and the
        step [s]."""
        mesh = self.wing.mesh
        f = self._normal_rate_section_forces(held, x[mesh.sections], v[mesh.sections], v_wind, mesh.section_tube_d,
                                             mesh.section_width)
        out = np.zeros((len(v), 3))
        if self._sections_partition:  # (each node in one section: no repeated index)
            out[mesh.sections.ravel()] = f.reshape(-1, 3)
        else:
            np.add.at(out, mesh.sections.ravel(), f.reshape(-1, 3))
        return out

    def _normal_rate_section_forces(self, held, x_sec, v_sec, v_wind, tube_d, width, spanwise=None):
        """The forces (n, m, 3) [N] of :meth:`normal_rate_force` on the nodes of sections ``x_sec``, ``v_sec`` (n,
        m, 3) (``held`` and the sections' data for the same ``n``; ``spanwise`` as :meth:`_frames_of`)."""
        n0, m_a, dt = held
        if self.compiled:  # the same forces in one compiled loop (kite_env.aero.kernels)
            return section_normal_rate_forces(x_sec, v_sec, n0, m_a, dt, tube_d, v_wind, spanwise)
        n1 = self._frames_of(x_sec, tube_d, width, spanwise).e_z
        n_dot = (n1 - n0) / dt  # (n, 3)
        W = self.section_weights(x_sec, "three_quarter_chord", tube_d)  # (n, m)
        v_rel = np.einsum("sj,sjk->sk", W, v_sec) - np.asarray(v_wind, float)[None, :]
        F = -(m_a * np.einsum("sk,sk->s", n_dot, v_rel))[:, None] * n1  # (n, 3)
        return W[:, :, None] * F[:, None, :]

    def normal_rate_tangent(self, held, x: np.ndarray, v: np.ndarray, v_wind: np.ndarray):
        """Section blocks (n_sec, 3 m, 3 m) of ``-d f / d x`` and ``-d f / d v`` of :meth:`normal_rate_force` at the
        iterate ``x``, ``v`` (node-major within each section, as ``Assembler.block_data`` takes them).

        The force grows with the rate of the section normals over the step, ``(n1 - n0) / dt``: its change with the
        iterate's positions is of the order ``m_a |v_rel| / (c dt)``, as large as the section damping's ``c_v C``
        for a section that turns fast against the flow, and larger in a step made in halves. Left out of the
        Newton tangent, a tumbling mid-wing section's Newton stalled at a residual of 960 N in a step of dt/16 and
        the flight ended (docs/model.md, "The trailing-edge hem"). The velocity part is exact (``f_j = W_j F`` with ``F
        =
        -m_a (n' . v_rel) n1`` and ``v_rel = sum_k W_k v_k - v_wind``: ``-df_j/dv_k = m_a W_j W_k n1 n'^T``); the
        position part (the normals' and the weights' change) by central differences of the force, every coordinate of
        every section perturbed in one stacked evaluation (each section's force acts on its own nodes and depends on
        them, and on its neighbours' LE nodes only through the LE-line tangent of a nearly flat section's frame,
        which is held, as in the loads' Jacobian)."""
        n0, m_a, dt = held
        mesh = self.wing.mesh
        sec = mesh.sections
        n_sec, m = sec.shape
        p = 3 * m
        # the 2 p perturbed copies of every section (coordinate q of each section by +-h) in one stacked call, the
        # LE-line tangent held at the unperturbed wing's (as the loads' Jacobian, kite_env.aero.loads)
        h = 1e-6
        x_sec = x[sec]
        xs = np.broadcast_to(x_sec, (2, p, n_sec, m, 3)).copy()
        q = np.arange(p)
        xs.reshape(2, p, n_sec, p)[0, q, :, q] += h
        xs.reshape(2, p, n_sec, p)[1, q, :, q] -= h
        def rep(a):
            return np.broadcast_to(np.asarray(a, dtype=float), (2 * p,) + np.shape(a)).reshape(
                (2 * p * n_sec,) + np.shape(a)[1:])

        held_rep = (rep(n0), rep(m_a), dt)
        f = self._normal_rate_section_forces(
            held_rep, xs.reshape(-1, m, 3), rep(v[sec]), v_wind, rep(mesh.section_tube_d), rep(mesh.section_width),
            spanwise=rep(spanwise_directions(x_sec[:, 0]))).reshape(2, p, n_sec, p)
        K = (-(f[0] - f[1]) / (2.0 * h)).transpose(1, 2, 0)  # (n_sec, 3 m (force), 3 m (coordinate))
        n1 = self.section_frames(x).e_z
        n_dot = (n1 - n0) / dt
        W = self.section_weights(x[sec], "three_quarter_chord")
        C = (m_a[:, None, None, None, None] * W[:, :, None, None, None] * W[:, None, None, :, None]
             * n1[:, None, :, None, None] * n_dot[:, None, None, None, :])
        return np.ascontiguousarray(K), C.reshape(n_sec, 3 * m, 3 * m)

    # ------------------------------------------------------------------ state
    def start(self, state: NodalState, v_nodes: np.ndarray, r_kcu, v_kcu, rest, g_K, v_wind) -> None:
        """Start from ``state`` moving with ``v_nodes`` (n_nodes, 3); the accelerations from the equation of motion
        at the start (``M a_0 = f_ext - f_int``, the rotations in equilibrium as they are)."""
        self.state = state.copy()
        self._prev = None
        self.solver.forget_factorization()  # the kept LU of the last flight: a start must not depend on it
        self.v = np.asarray(v_nodes, float).copy()
        self.a = np.zeros_like(self.v)
        self.r_prev = np.zeros(self.wing.n_dof)
        self.carry = None
        self.rayleigh_held = None
        self.w = np.zeros_like(self.v)  # (the start's load: no rotation over its "step")
        self.aw = np.zeros_like(self.v)
        self.update_mass()
        load = StepLoad(self, 1.0, r_kcu, v_kcu, rest, g_K, v_wind)
        load.x_pred = self.state.x  # a = 0 at the iterate, v = v_nodes
        load.v_pred = self.v
        load.force(self.state)
        f_int, _ = self.solver.asm.assemble(self.state.x, self.state.Rn, tangent=False)
        r = f_int - load.f_phys
        r[self.solver.auto_fixed] = 0.0
        self.a = -np.linalg.solve(self.M_blocks, r.reshape(-1, 6)[:, :3, None])[:, :, 0]  # M a_0 + r_0 = 0
        if self.hold_bridle:  # held: no acceleration (their residual is the support's force)
            self.a[self.bridle] = 0.0
            self.v[self.bridle] = 0.0
        self.r_prev = r
        # rotations: the wing turns rigidly at the start, with the angular accelerations of M a_0 + r_0 = 0
        _, w = self.rigid_velocity()
        self.w = np.repeat(w[None, :], len(self.v), axis=0)
        J = self.J_node
        ok = J > 0.0
        self.aw[ok] = -r.reshape(-1, 6)[ok, 3:] / J[ok, None]

    def rebase(self, Q: np.ndarray, p: np.ndarray) -> None:
        """Re-express the state in a new frame: ``x' = Q x + p``, vectors ``Q v``, rotations ``Q R``."""
        st = self.state
        self.state = NodalState(st.x @ Q.T + p, Q @ st.Rn)
        self.v = self.v @ Q.T
        self.a = self.a @ Q.T
        self.w = self.w @ Q.T
        self.aw = self.aw @ Q.T
        r6 = self.r_prev.reshape(-1, 2, 3) @ Q.T
        self.r_prev = r6.reshape(-1)
        if self.carry is not None:
            self.carry = ((self.carry[0].reshape(-1, 2, 3) @ Q.T).reshape(-1), self.carry[1])
        if self.rayleigh_held is not None:
            kd, kb, age, Q0 = self.rayleigh_held
            self.rayleigh_held = (kd, kb, age, Q @ Q0)
        self.wing.state = self.state
        if self._prev is not None:
            prev, dt_prev = self._prev
            self._prev = (NodalState(prev.x @ Q.T + p, Q @ prev.Rn), dt_prev)

    def step(self, dt: float, r_kcu, v_kcu, rest, g_K, v_wind, flight: FlightState):
        """One generalized-alpha step of ``dt`` with the KCU at ``r_kcu`` (its velocity ``v_kcu``) at the end of the
        step, steering rest lengths ``rest`` (4,), gravity ``g_K`` and wind ``v_wind`` (3,) in the step's frame.
        ``flight`` (the frame's motion) only decomposes the totals into lift and drag. Returns the
        :class:`WingSolution` (``F_b``: the bridle lines' forces on A-D) and commits the new state; raises
        :class:`WingConvergenceError` and leaves the state as it was when Newton fails."""
        wing = self.wing
        fcfg = wing.cfg.fsi
        pred = start = self._predict(dt)
        self.update_mass(start.x)

        def step_load() -> StepLoad:
            ld = StepLoad(self, dt, r_kcu, v_kcu, rest, g_K, v_wind, at=pred)
            if self.section_added_mass is not None:
                ld.normal_rate = (self.section_frames(self.state.x).e_z, self.section_added_mass, dt)
            return ld

        load = step_load()
        history: list[dict] = []
        res = None
        for attempt in range(2):
            try:
                res = self.solver.solve(start, None, self.held_dofs, load=load, tol_force=fcfg.tol_force_rel,
                                        tol_disp=fcfg.tol_disp_m, accept_force=fcfg.accept_force_rel)
                break
            except ConvergenceError as exc:
                history.append({"iter": len(history) + 1, "newton_iters": len(exc.history), "dx_max_m": np.nan,
                                "dload_rel": np.nan,
                                "residual_history": exc.history, "dynamic": True})
                self.solver.forget_factorization()
                if attempt == 1:
                    raise WingConvergenceError(f"dynamic wing step failed: {exc}", history) from exc
                start = self.state.copy()
                if self.rayleigh_held is not None:
                    # the structural damping's tangent held from up to rayleigh_tangent_period_s before is the
                    # shape's of then: in a fast collapse it no longer describes the wing. The retry, and the
                    # steps in halves after it fails (FlightSimulator.step), assemble it at their own start
                    # (docs/model.md, "Structural damping")
                    self.rayleigh_held = None
                    load = step_load()
        st = res.state
        if res.accepted:
            load.force(st)
        a, v = load.kinematics(st)
        aw, w = load.rotation_kinematics(st) if self.has_rotary_inertia else (self.aw, self.w)
        r = res.reactions + (load.f_eff - load.f_phys)
        r[self.solver.auto_fixed] = 0.0
        history.append({"iter": len(history) + 1, "newton_iters": res.iterations, "residual_N": res.history[-1][1],
                        "dx_max_m": res.history[-2][2] if len(res.history) > 1 else 0.0, "dload_rel": 0.0,
                        "factorizations": res.factorizations, "accepted": res.accepted, "method": "dynamic"})
        self._prev = (self.state, dt)
        self.state, self.v, self.a, self.r_prev = st, v, a, r
        if load.K0_fresh:
            self.rayleigh_held = (load.K0, load.Kb_at, 0.0, np.eye(3))
        elif self.rayleigh_held is not None:
            kd, kb, age, Q0 = self.rayleigh_held
            self.rayleigh_held = (kd, kb, age + dt, Q0)
        # the unbalanced force correction: the residual f_eff - f_int that Newton leaves (within its tolerance; on
        # the free DOF, -reactions) goes into the next step's load with the same impulse (rho dt), so the momentum
        # that a step misses is delivered one step late and the misses do not add up over a flight. "sections": only
        # what moves the sections as a whole (section_resultant_load; docs/performance.md, "The carried residual")
        rho = -res.reactions
        rho[self.solver.auto_fixed] = 0.0
        rho[self.held_dofs] = 0.0
        self.carry = (self.section_resultant_load(rho) if self.carry_residual == "sections" else rho, dt)
        self.w, self.aw = w, aw
        wing.state = st
        T, _, e = load.line
        F_b = r.reshape(-1, 6)[self.bridle, :3].copy() if self.hold_bridle else -T[:, None] * e
        sol = wing.solution(st, load.loads, F_b, flight, history, res.iterations, load.collapsed, res.accepted)
        return sol

    def _predict(self, dt: float) -> NodalState:
        """Start of Newton: the last step's change of shape repeated (positions ``x_n + r (x_n - x_n-1)``, rotations
        turned again by their last change, ``r = dt / dt_n-1``; as :meth:`AeroelasticWing._predict`), or on the first
        step the wing moved rigidly with its mass-weighted rigid-body velocity. Not ``x_n + dt v_n``: the velocities
        of the stiff, light modes (a tip node of grams on its rod) are large and alternate from step to step under
        the numerical damping while their displacements stay small."""
        st = self.state
        if self._prev is None:
            V, w = self.rigid_velocity()
            return NodalState(st.x + dt * (V[None, :] + np.cross(w[None, :], st.x)), expm(dt * w) @ st.Rn)
        prev, dt_prev = self._prev
        r = min(dt / dt_prev, 2.0)
        D = st.Rn @ prev.Rn.transpose(0, 2, 1)
        if r != 1.0:
            D = expm(r * logm(D))
        Rn = D @ st.Rn
        return NodalState(st.x + r * (st.x - prev.x), 0.5 * (Rn @ (3.0 * np.eye(3) - Rn.transpose(0, 2, 1) @ Rn)))

    def rigid_velocity(self, v: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Mass-weighted least-squares rigid-body fit of the nodal velocities ``v`` (n_nodes, 3) (default: the
        current ones) at the current positions: ``(V, omega)`` with the velocity field ``V + omega x x`` (structural
        masses; frame of the step)."""
        m, x = self.m_node, self.state.x
        v = self.v if v is None else v
        fit = self._rigid_fit
        if fit is None or fit[0] is not x:  # the mass centre and the inverse inertia of the current shape
            M = m.sum()
            c = (m @ x) / M
            r = x - c
            mr = m[:, None] * r
            B = mr.T @ r  # sum m r r^T
            fit = self._rigid_fit = (x, M, c, mr, np.linalg.inv(np.trace(B) * np.eye(3) - B))
        _, M, c, mr, J_inv = fit
        vc = (m @ v) / M
        A = mr.T @ v  # H = sum m r x (v - vc) = sum m r x v (sum m r = 0): the skew part of sum m r v^T
        w = J_inv @ np.array([A[1, 2] - A[2, 1], A[2, 0] - A[0, 2], A[0, 1] - A[1, 0]])
        return vc - cross(w, c), w

    def section_resultant_load(self, rho: np.ndarray) -> np.ndarray:
        """The part of a nodal load ``rho`` (n_dof,) that each chordwise section carries as a whole: per section,
        the nodal forces ``f_j = m_j (A + alpha x r_j)`` (n_dof,; translations only) with the section's resultant
        force and its moment about the section's mass centre (forces and the moments at the rotational DOF), the
        section's nodes ``j`` at ``r_j`` from that centre with their structural masses ``m_j`` (a rigid section's
        inertial load). The moment about the section's axis of least inertia, its chord line, is left out: the
        nodes lie a tenth of their chordwise spread from that line (its inertia 1 % of the other two), so it would
        take large opposing forces on nodes centimetres apart; the wing's bending about that axis is carried by the
        sections' forces. Used to carry a step's unbalanced residual (``structure.carry_residual``)."""
        sec = self.wing.mesh.sections
        m, x = self.m_node[sec], self.state.x[sec]  # (n_sec, k), (n_sec, k, 3)
        Ms = m.sum(axis=1)
        r = x - (np.einsum("sk,ski->si", m, x) / Ms[:, None])[:, None, :]
        r6 = rho.reshape(-1, 6)
        F = r6[sec, :3].sum(axis=1)
        Mo = cross(r, r6[sec, :3]).sum(axis=1) + r6[sec, 3:].sum(axis=1)
        B = np.einsum("sk,ski,skj->sij", m, r, r)
        J = np.trace(B, axis1=1, axis2=2)[:, None, None] * np.eye(3) - B  # the section's inertia tensor
        lam, V = np.linalg.eigh(J)  # (ascending: V[:, :, 0] the chord line)
        al = np.einsum("sij,sj,sj->si", V[:, :, 1:], 1.0 / lam[:, 1:], np.einsum("sji,sj->si", V[:, :, 1:], Mo))
        out = np.zeros_like(r6)
        out[sec.ravel(), :3] = (m[:, :, None] * (F[:, None, :] / Ms[:, None, None]
                                                  + cross(al[:, None, :], r))).reshape(-1, 3)
        return out.reshape(-1)

    def kinetic_energy(self) -> float:
        """``1/2 sum v . M v + 1/2 sum J |w|^2`` [J] with the current mass blocks (structural and added mass) and the
        nodes' rotary inertia."""
        return 0.5 * float(np.einsum("ni,nij,nj->", self.v, self.M_blocks, self.v)) \
            + 0.5 * float(np.einsum("n,ni,ni->", self.J_node, self.w, self.w))
