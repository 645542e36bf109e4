"""Static aeroelastic coupling of the wing (Bosch et al., Sect. II, Fig. 2; Eq. 1-9).

For prescribed bridle-point positions ``q_b`` and a flight state ``X`` (kite velocity, angular velocity, wind), the
structure and the steady aerodynamic load model are alternated until the shape and the loads stop changing:

1. aero loads ``F_a(q, X)`` on the current shape (Eq. 2-9, :mod:`kite_env.aero`),
2. Newton-Raphson on the first block of Eq. (1) with ``F_a`` held fixed (:mod:`kite_env.structure.solver`),
3. the inflated-tube stiffness ``EI(p, d, q)`` updated from the new shape (secant, :mod:`kite_env.structure.tube`),

until the largest nodal position change between coupling iterations is below ``fsi.tol_disp_m`` and the aero load
vector changes by less than ``fsi.tol_force_rel`` of its norm. The reactions ``F_b`` at A-D follow from the second
block of Eq. (1). Everything is expressed in the kite frame K (:mod:`kite_env.frames`).

Two ways to hold the bridle points:

* ``support="prescribed"``: A-D fixed at ``q_b`` (the dynamic model's boundary condition, Sect. II.C).
* ``support="lines"``: for static analyses (polar, steady cases) the x_k and z_k coordinates of A-D are prescribed
  while their y_k coordinates are free and pulled towards a fixed kite control unit by the bridle-line tension
  (the line force along the line, its tension taken from the reaction of the previous coupling iteration). This is
  how the wing tips are drawn together under load in flight (paper, Sect. IV.C) without solving the flight dynamics.

Failure to converge raises :class:`WingConvergenceError` with the coupling history; nothing returns NaN silently.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from kite_env.aero.loads import (
    LUFFING_BAND_CL,
    load_jacobian,
    oswald_efficiency,
    projected_planform,
    section_damping,
    section_loads,
    wing_totals,
)
from kite_env.config import Config
from kite_env.geometry.mesh import BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP, KiteMesh
from kite_env.structure import rotations, tube
from kite_env.structure.assembly import Assembler
from kite_env.structure.beam import BeamSet
from kite_env.structure.hem import HemSet
from kite_env.structure.shell import ShellSet
from kite_env.structure.solver import ConvergenceError, NodalState, StaticSolver
from kite_env.structure.tube_kernels import tube_secants

#: Poisson ratio used to derive the shear modulus of the solid tip rod and TE wire (G = E / (2 (1 + nu))).
_NU_ROD = 0.3


class WingConvergenceError(RuntimeError):
    """The static aeroelastic problem did not converge; ``history`` holds one dict per coupling iteration."""

    def __init__(self, message: str, history: list[dict]):
        lines = [message, "coupling history (iter, max|dx| [m], rel. load change, newton iters):"]
        for h in history[-12:]:
            if "iter" in h:
                lines.append(f"  {h['iter']:3d}  {h['dx_max_m']:.3e}  {h['dload_rel']:.3e}  {h['newton_iters']}")
            elif "retry" in h:
                lines.append(f"  retry {h['retry']} with {h['n_sub']} bridle sub-steps")
            elif "cutback" in h:
                lines.append(f"  load increment to scale {h['cutback']:.4g} halved")
        super().__init__("\n".join(lines))
        self.history = history


@dataclass(frozen=True)
class FlightState:
    """Wing state vector X of the paper, in frame K: ``v_kite`` [m/s], ``omega`` [rad/s], ``v_wind`` [m/s]."""

    v_kite: np.ndarray
    omega: np.ndarray
    v_wind: np.ndarray

    @classmethod
    def wind_tunnel(cls, airspeed_mps: float, alpha_rad: float, sideslip_rad: float = 0.0) -> FlightState:
        """Kite at rest in a uniform flow of ``airspeed_mps`` at kite angle of attack ``alpha_rad``.

        The kite angle of attack is the angle between the inflow (air relative to the kite) and ``x_k`` in the
        ``x_k``-``z_k`` plane, positive for inflow from the ``-z_k`` side; sideslip rotates the inflow towards ``+y_k``.
        """
        ca, sa = np.cos(alpha_rad), np.sin(alpha_rad)
        cb, sb = np.cos(sideslip_rad), np.sin(sideslip_rad)
        flow = airspeed_mps * np.array([ca * cb, sb, sa * cb])
        return cls(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow)


@dataclass
class WingSolution:
    """Result of one static aeroelastic solve (all vectors in frame K, SI units)."""

    F_b: np.ndarray  # (4, 3) reaction forces at A, B, C, D on the wing [N]; the wing pulls its bridle with -F_b
    nodes: np.ndarray  # (n_nodes, 3) deformed node positions [m]
    alpha: np.ndarray  # (n_sec,) section angles of attack [rad]
    CL: np.ndarray
    CD: np.ndarray
    CM: np.ndarray
    aero_force: np.ndarray  # (3,) total aerodynamic force [N]
    lift: float  # [N], perpendicular to the apparent wind at the kite origin
    drag: float  # [N], along the apparent wind
    coupling_iters: int
    newton_iters: int
    history: list[dict] = field(default_factory=list)
    tube_collapsed: np.ndarray | None = None  # (n_beams,) bool
    section_forces: np.ndarray | None = None  # (n_sec, m, 3) [N]
    accepted: bool = False  # a Newton solve stalled within fsi.accept_force_rel instead of fsi.tol_force_rel
    section_lift: np.ndarray | None = None  # (n_sec,) magnitude of each section's lift, Eq. (7) [N]
    section_drag: np.ndarray | None = None  # (n_sec,) magnitude of each section's drag, Eq. (8) [N]
    aero_moment: np.ndarray | None = None  # (3,) moment of the aerodynamic nodal forces about r_k, frame K [N m]

    @property
    def lift_to_drag(self) -> float:
        return self.lift / self.drag if self.drag > 0 else float("inf")


def _rod_section(E: float, d: np.ndarray):
    A = np.pi * d**2 / 4.0
    I = np.pi * d**4 / 64.0
    G = E / (2.0 * (1.0 + _NU_ROD))
    return E * A, E * I, E * I, G * 2.0 * I


class AeroelasticWing:
    """The quasi-static aeroelastic wing: FE structure (shells + beams) coupled with section aerodynamics.

    Parameters
    ----------
    mesh : KiteMesh
        Unloaded design mesh in frame K.
    cfg : Config
        Uses ``cfg.structure``, ``cfg.aero`` and ``cfg.fsi``.
    """

    def __init__(self, mesh: KiteMesh, cfg: Config | None = None):
        self.mesh = mesh
        self.cfg = cfg or Config()
        s = self.cfg.structure
        kind = mesh.beam_kind
        d = mesh.beam_diameter
        n_b = len(kind)
        self._is_tube = (kind == BEAM_LE) | (kind == BEAM_STRUT)
        self._tube_rows = np.flatnonzero(self._is_tube)
        EA, EI2, EI3, GJ = (np.zeros(n_b) for _ in range(4))
        self.tube_props = tube.tube_properties(s.tube_pressure_Pa, d[self._is_tube])
        EA[self._is_tube] = np.pi * d[self._is_tube] * s.tube_wall_Et_N_per_m
        EI2[self._is_tube] = EI3[self._is_tube] = self.tube_props.EI0
        GJ[self._is_tube] = self.tube_props.GJ0
        for code, E in ((BEAM_TIP, s.tip_rod_E_Pa), (BEAM_TE, s.te_wire_E_Pa)):
            sel = kind == code
            EA[sel], EI2[sel], EI3[sel], GJ[sel] = _rod_section(E, d[sel])
        # The trailing edge is a hem of folded canopy and seam tape around the wire, not a bare 2 mm wire. Its
        # bending stiffness is not given in the paper; a bare wire (4e-4 N m^2) leaves the compressed mid-span TE a
        # mechanism that flaps without a static equilibrium (Newton wanders). We use a hem stiffness
        # ``te_hem_EI_Nm2`` (default 0.4 N m^2, the order of a 25 mm double-layer Dacron tape, E t w^3/12 with
        # E t = 2e5 N/m), documented as a modelling choice in the README.
        te = kind == BEAM_TE
        EI2[te] = np.maximum(EI2[te], s.te_hem_EI_Nm2)
        EI3[te] = np.maximum(EI3[te], s.te_hem_EI_Nm2)
        GJ[te] = np.maximum(GJ[te], s.te_hem_EI_Nm2 / (1.0 + _NU_ROD))
        # the hem is taken out of the co-rotational beams (their rows stay, without stiffness, so that the beams keep
        # the mesh's numbering) into frame-free rods with its axial, bending and torsional stiffness
        # (kite_env.structure.hem; docs/model.md, "The trailing-edge hem")
        self.hem = None
        if np.any(te):
            self.hem = HemSet(mesh.beams[te], mesh.nodes, np.asarray(mesh.beam_up)[te], EA[te],
                              0.5 * (EI2[te] + EI3[te]), GJ[te])
            EA[te] = EI2[te] = EI3[te] = GJ[te] = 0.0
        self.beams = BeamSet(mesh.beams, mesh.nodes, mesh.beam_up, EA, EI2, EI3, GJ)
        rods = [] if self.hem is None else [self.hem]
        # the conservative law with the fold contact of a kinked tube (structure.tube_fold_onset_deg; the larger-end
        # law and the continuation through it keep Breukels' law alone)
        self._tube_props_fold = self.tube_props
        if s.tube_fold_onset_deg > 0.0:
            self._tube_props_fold = tube.tube_properties(s.tube_pressure_Pa, d[self._is_tube],
                                                         self.beams.L0[self._is_tube],
                                                         np.deg2rad(s.tube_fold_onset_deg))
        self.shells = ShellSet(mesh.shells, mesh.nodes, s.canopy_E_Pa, s.canopy_nu, s.canopy_thickness_m,
                               wrinkling=s.wrinkling, shear_ratio=s.canopy_shear_ratio,
                               kinematics=s.membrane_kinematics)
        self.assembler = Assembler(mesh.n_nodes, [self.beams, self.shells, *rods])
        self.solver = StaticSolver(self.assembler)
        self.lines = BridleLines(mesh.bridle)
        self._lines_solver = StaticSolver(Assembler(mesh.n_nodes, [self.beams, self.shells, *rods, self.lines]))
        # monolithic Newton on structure + aero loads: the pattern includes the section blocks of the aero load
        # Jacobian; mode "modified" keeps the factorisation across calls (time steps) while it still contracts
        self._mono_solvers = {
            "prescribed": StaticSolver(Assembler(mesh.n_nodes, [self.beams, self.shells, *rods],
                                                 extra_blocks=mesh.sections),
                                       mode="modified", max_iter=self.cfg.fsi.max_newton_iter, contraction=0.5),
            "lines": StaticSolver(Assembler(mesh.n_nodes, [self.beams, self.shells, *rods, self.lines],
                                            extra_blocks=mesh.sections), mode="modified", contraction=0.5,
                                  max_iter=self.cfg.fsi.max_newton_iter),
        }
        self.bridle = np.asarray(mesh.bridle)
        # induced drag (aero.induced_drag, downwashed): the unloaded wing's projected planform and span efficiency
        span, self.planform_area_m2 = projected_planform(mesh.nodes[mesh.sections])
        self.aspect_ratio = span * span / self.planform_area_m2
        self.span_efficiency = oswald_efficiency(self.aspect_ratio)
        self._downwash: tuple[float, np.ndarray] | None = None  # (induced angle [rad], net-lift direction in K)
        self._free_flight: FlightState | None = None  # the flight state without the downwash (lift/drag totals)
        self._last_downwash_change = 0.0
        self.n_dof = 6 * mesh.n_nodes
        # translational DOF of the section load points, in the order of SectionLoads.nodal_forces.ravel()
        self._load_dofs = (6 * mesh.sections[:, :, None] + np.arange(3)).ravel()
        self.state = self.unloaded_state()
        self._sec_prev: np.ndarray | None = None  # section node positions at the previous time step (Eq. 3)
        self._cm_ref: float | None = None  # C_M reference point during a cold start's continuation
        # a cold start of the conservative tube law: the ramp with the larger-end law, the last solve with the exact
        # tangent of the conservative one (solve)
        self._tube_law: str | None = None
        self._exact_tube_tangent = False
        self._C_damp: np.ndarray | None = None  # (n_sec, 3, 3) section damping of the current time step [N s/m]
        self._step_prev: tuple | None = None  # (state, dt) before the last committed time step (predictor)
        self._kb_cache: tuple | None = None  # (factorisation count, bridle stiffness)
        self._damped = False  # retry mode of the monolithic solve (StaticSolver.solve_damped)
        # kite control unit for support="lines": below the tip mid-chord, power-line length from the paper (Table 1)
        self.line_length_m = 25.0

    # ------------------------------------------------------------------ state handling
    def unloaded_state(self) -> NodalState:
        n = self.mesh.n_nodes
        return NodalState(self.mesh.nodes.copy(), np.broadcast_to(np.eye(3), (n, 3, 3)).copy())

    def reset(self) -> None:
        """Forget everything the previous solves left (next solve starts from the unloaded wing, as on a wing just
        built): the warm start, the kept factorisations of the modified Newton, the tubes' secant stiffness of the
        last state, the line tensions. Without it a cold start after another flight took a different Newton path
        and converged elsewhere within the tolerance (a start differed with the episodes before it)."""
        self.state = self.unloaded_state()
        self._sec_prev = None
        self._step_prev = None
        self._downwash = None
        self._free_flight = None
        self._last_downwash_change = 0.0
        self._C_damp = None
        self._kb_cache = None
        self._damped = False
        for solver in (self.solver, self._lines_solver, *self._mono_solvers.values()):
            solver.forget_factorization()
        self.lines.tension[:] = 1.0
        self.update_tube_stiffness(self.state)

    def _predict(self, dt: float | None) -> NodalState:
        """Start of a warm time step: the last solution, linearly extrapolated in time when the two previous
        committed solves were time steps: positions ``x + r (x - x_prev)``, rotations
        ``expm(r log(R R_prev^T)) R`` with ``r = dt / dt_prev`` (at most 2; for equal steps simply
        ``R R_prev^T R``, re-orthonormalised). Without the rotations a warm step needs about 3 Newton iterations
        instead of 1.3. Only the start of Newton changes."""
        prev = self._step_prev
        if not dt or prev is None or prev[1] is None:
            return self.state.copy()
        st_prev, dt_prev = prev
        r = min(dt / dt_prev, 2.0)
        x = self.state.x + r * (self.state.x - st_prev.x)
        D = self.state.Rn @ st_prev.Rn.transpose(0, 2, 1)  # rotation over the last step
        if r != 1.0:
            D = rotations.expm(r * rotations.logm(D))
        Rn = D @ self.state.Rn
        # one Newton-Schulz step back onto SO(3), R <- R (3 I - R^T R) / 2: without it the round-off of the
        # products grows from step to step (each prediction compounds the last two) and ruins the rotations
        return NodalState(x, 0.5 * (Rn @ (3.0 * np.eye(3) - Rn.transpose(0, 2, 1) @ Rn)))

    def bridle_stiffness(self) -> np.ndarray:
        """(12, 12) derivative of ``F_b`` (A, B, C, D x, y, z in K) with respect to the bridle positions ``q_b``, the
        wing in aeroelastic equilibrium (monolithic tangent incl. the aero load Jacobian; for a time step it contains
        the 1/dt deformation-velocity terms of Eq. 3). From the factorisation of the last prescribed-support solve,
        recomputed only when that factorisation changed."""
        solver = self._mono_solvers["prescribed"]
        if self._kb_cache is None or self._kb_cache[0] != solver.n_factorizations:
            dofs = (6 * self.bridle[:, None] + np.arange(3)[None, :]).ravel()
            self._kb_cache = (solver.n_factorizations, solver.condensed_tangent(dofs))
        return self._kb_cache[1]

    @property
    def design_bridle(self) -> np.ndarray:
        """(4, 3) unloaded positions of A, B, C, D in frame K [m]."""
        return self.mesh.nodes[self.bridle].copy()

    @property
    def prescribed_assembly(self) -> Assembler:
        """The :class:`~kite_env.structure.assembly.Assembler` of the wing's structure (beams, shells, hem) whose
        sparsity pattern includes the section blocks of the aero load Jacobian: that of the monolithic solve with A-D
        prescribed. For operators on the wing's DOF built outside its static solve (the wing with inertia's Newton
        solve and operators, linearisations of the wing): their matrices share this pattern."""
        return self._mono_solvers["prescribed"].asm

    def kcu_position(self) -> np.ndarray:
        """Design KCU position in K used by ``support="lines"``: on the symmetry plane below the tip mid-chord,
        at the power-line length (Table 1: L_A = L_C = 25 m) from A and C."""
        a, b = self.mesh.nodes[self.bridle[0]], self.mesh.nodes[self.bridle[1]]
        x = 0.5 * (a[0] + b[0])
        h = np.sqrt(max(self.line_length_m**2 - a[1] ** 2 - (x - a[0]) ** 2, 1.0))
        return np.array([x, 0.0, a[2] - h])

    # ------------------------------------------------------------------ pieces of the coupling loop
    def update_tube_stiffness(self, state: NodalState, material_tangent: bool = True) -> np.ndarray:
        """Secant EI(p, d, kappa) and GJ(p, d, phi) of the tubes from the current element deformation, with the
        material terms of the law's tangent when the law is evaluated at every iterate (``material_tangent``; False
        where the stiffness is held over a Newton solve, as in the partitioned coupling: the law is linear there).
        Sets the tube rows of :attr:`beams` (what every later assembly of the wing's structure sees): called at each
        iterate of the wing's own solves, of the wing with inertia (:mod:`kite_env.dynamics.wing_dynamics`) and before
        a linearisation at ``state``.

        Returns the per-beam collapse flag (curvature beyond Breukels' collapse curvature)."""
        tb = self._is_tube
        l, th = self.beams.local_rotations(state.x[self.mesh.beams], state.Rn[self.mesh.beams])
        measure = "element_energy" if self._tube_law is None else self._tube_law
        p = self._tube_props_fold if measure == "element_energy" else self.tube_props
        # the energy's curvature is per unloaded length; the larger-end law of a cold solve's continuation takes the
        # current chord length (as it always has: the cold starts unchanged)
        L_k = self.beams.L0 if measure == "element_energy" else l
        if self.beams.backend == "numba":  # the same formulas in one compiled loop (tested against the lines below)
            n_t = self._tube_rows.size
            EI, GJ, gb, gt = (np.empty(n_t) for _ in range(4))
            col = np.empty(n_t, dtype=np.bool_)
            tube_secants(th, L_k, self._tube_rows, p.EI0, p.M_max, p.kappa_collapse, p.GJ0, p.c2, p.kappa_fold,
                         p.kappa_closed, measure == "element_energy", material_tangent, EI, GJ, col, gb, gt)
        else:
            th1, th2, L0 = th[tb, 0], th[tb, 1], L_k[tb]
            kappa = tube.element_curvature(th1, th2, L0, measure)
            phi = np.abs(th2[:, 0] - th1[:, 0]) / L0
            EI, GJ, col = tube.secant_EI(p, kappa), tube.secant_GJ(p, phi), tube.collapsed(p, kappa)
            # the consistent tangent exists for the energy-derived law only
            gb, gt = (tube.secant_material_terms(p, kappa, phi, L0) if measure == "element_energy" and material_tangent
                      else (None, None))
        self.beams.set_bending_torsion(self._tube_rows, EI, GJ, gb, gt)
        collapsed = np.zeros(len(self.mesh.beams), bool)
        collapsed[tb] = col
        return collapsed

    def strain_energy(self, state: NodalState) -> float:
        """Stored elastic energy [J] of the wing at ``state``: the canopy shells, the tip rods and trailing-edge
        wire, and the inflated tubes with Breukels' law as the energy ``L0 (W(kappa) + W_t(phi))`` of
        :mod:`kite_env.structure.tube` (the conservative tube law, at each element's rms curvature)."""
        b, m, tb = self.beams, self.mesh, self._is_tube
        xb, Rb = state.x[m.beams], state.Rn[m.beams]
        l, th = b.local_rotations(xb, Rb)
        L0 = b.L0[tb]
        kappa = tube.element_curvature(th[tb, 0], th[tb, 1], L0)
        phi = np.abs(th[tb, 1, 0] - th[tb, 0, 0]) / L0
        u_tube = L0 * (tube.bending_energy_density(self._tube_props_fold, kappa)
                       + tube.torsion_energy_density(self.tube_props, phi)) + 0.5 * b.EA[tb] / L0 * (l[tb] - L0) ** 2
        u_rest = b.energy(xb, Rb)[~tb]
        u_hem = 0.0 if self.hem is None else self.hem.energy(state.x[self.hem.conn], state.Rn[self.hem.conn]).sum()
        return float(u_tube.sum() + u_rest.sum() + u_hem
                     + self.shells.energy(state.x[m.shells], state.Rn[m.shells]).sum())

    #: points (/chord) the regression CM is stepped through from a cold start (``_cm_continuation``)
    CM_CONTINUATION_START = 0.25
    CM_CONTINUATION_STEP = 0.05

    def continuation(self, state, start: float, target: float, h0: float, solve_at, history) -> NodalState:
        """Continuation of a cold solve in one parameter from ``start`` to ``target`` in steps of at most ``h0``,
        each converged (``solve_at(state, value)`` returns the converged state at ``value``). A step whose solve fails
        is halved (down to ``h0 / 64``; then the failure is raised) and grows back after each converged one:
        automatic incrementation with cutback (Crisfield, *Non-linear Finite Element Analysis of Solids and
        Structures*, Vol. 1, Wiley 1991, ch. 9). A failed step leaves the last converged state and line tensions.
        Only the path to the equilibrium changes. Used by the cold solve's load ramp and C_M continuation, and by a
        simulator's start whose cold solve fails (a continuation in the kite's speed, ``solve_at`` a warm
        :meth:`solve`); ``history`` collects the cutbacks."""
        sign = 1.0 if target >= start else -1.0
        current, h = start, h0
        while sign * (target - current) > 1e-12:
            nxt = current + sign * min(h, sign * (target - current))
            tension = self.lines.tension.copy()
            try:
                state = solve_at(state, nxt)
            except WingConvergenceError:
                self.lines.tension[:] = tension
                for solver in self._mono_solvers.values():
                    solver.forget_factorization()
                h *= 0.5
                if h < h0 / 64:
                    raise
                history.append({"cutback": nxt})
                continue
            current = nxt
            h = min(2.0 * h, h0)
        return state

    def _cold_ramp(self, state, q_b, flight, dt, support, last, h0, history, step):
        """The dynamic-pressure ramp of a cold solve: from the unloaded wing to the load scale ``last`` in increments
        of ``h0`` (``1 / fsi.cold_load_steps``) by :meth:`continuation`. From the unloaded wing, whose canopy is
        slack and whose tangent is nearly singular, the fixed first sixth of the load was too far for Newton in 20 %
        of the randomized starts of ``kite-eval end-reasons`` (docs/model.md, "The conservative tube law")."""
        return self.continuation(state, 0.0, last, h0,
                                 lambda st, scale: step(st, q_b, flight, dt, support, scale, history)[0], history)

    def _cm_continuation(self, state, q_b, flight, dt, support, ramp, history, step, method):
        """A cold solve with Breukels' C_M taken about a point ahead of the quarter chord (``aero.
        cm_regression_ref_over_c`` < 0.25, e.g. the nose) is reached by continuation (:meth:`continuation`): the
        load ramp with the C_M about the quarter chord, then the point moved forward in steps of 0.05 c, each
        converged. From the unloaded wing directly it fails: there the mid sections sit at alpha of about 0.3 deg,
        where the centre of pressure of a nose-referenced C_M lies far ahead of the nose and pushes the aft canopy
        to the pressure side. Returns the state to start the final solve from."""
        target = self.cfg.aero.cm_regression_ref_over_c
        if target >= self.CM_CONTINUATION_START:
            return state

        def solve_at(st, ref):
            self._cm_ref = float(ref)
            return self._attempts(st, st.x[self.bridle].copy(), q_b, 1, False, flight, dt, support, ramp[-1],
                                  history, step, method)[0]

        return self.continuation(state, self.CM_CONTINUATION_START, target, self.CM_CONTINUATION_STEP, solve_at,
                                 history)

    def aero_options(self) -> dict:
        """Keyword arguments of :func:`kite_env.aero.loads.section_loads` (and of ``section_damping`` and
        ``load_jacobian``) from ``cfg.aero``: the options every evaluation of this wing's section loads takes, inside
        its solves or outside them (the wing with inertia, linearisations), so that all see the same load model (during
        a cold solve's C_M continuation, the continuation's reference point)."""
        a = self.cfg.aero
        return dict(moment_chord_power=a.moment_chord_power, luffing_cl=LUFFING_BAND_CL if a.canopy_luffing else 0.0,
                    cm_regression_ref_over_c=a.cm_regression_ref_over_c if self._cm_ref is None else self._cm_ref,
                    rotation_point_over_c=0.75 if a.rotation_point == "three_quarter_chord" else None,
                    negative_alpha=a.negative_alpha)

    # ------------------------------------------------------------------ induced drag (aero.induced_drag)
    def downwashed(self, flight: FlightState) -> FlightState:
        """The flight state with the wing's induced downwash added to the wind at every section: Prandtl's lifting
        line with an elliptic loading, a uniform induced velocity ``w = -alpha_i V e_L`` opposite to the wing's net
        lift, ``alpha_i = C_L / (pi e AR)`` (Anderson, *Fundamentals of Aerodynamics*, 5th ed., Sect. 5.3.1, Eq.
        5.42-5.43; ``e`` from Raymer's estimate, :func:`kite_env.aero.loads.oswald_efficiency`, at the projected
        aspect ratio). Each section's inflow turns by ``alpha_i`` where its plane contains ``e_L`` (the mid-wing) and
        hardly at the near-vertical tips; its lift tilts back with the inflow, which is the induced drag, ``D_i =
        alpha_i L`` in total. ``C_L`` and ``e_L`` are those of the last committed solution (held over a time step,
        iterated to a fixed point at a cold start in :meth:`solve`)."""
        self._free_flight = flight
        if not self.cfg.aero.induced_drag or self._downwash is None:
            return flight
        alpha_i, e_L = self._downwash
        V = float(np.linalg.norm(flight.v_kite - flight.v_wind))
        return dataclasses.replace(flight, v_wind=flight.v_wind - alpha_i * V * e_L)

    def update_downwash(self, sol: WingSolution, flight: FlightState, dt: float | None = None) -> float:
        """Induced angle and lift direction from a solution at the free ``flight``; returns the change of the angle.

        In a time step (``dt``) the induced angle follows its quasi-steady value with a first-order lag of time
        constant ``tau = b / (2 V)``, the time the air takes to pass half the span: the trailing wake, and with it the
        downwash, builds up over a few chord lengths of travel after a change of lift (Wagner's indicial response of
        the circulation and its finite-wing form by R. T. Jones, NACA Report 681, 1940). Without the lag the induced
        angle, computed from the previous step's lift, over-corrects from step to step (the explicit fixed-point
        iteration of a quantity that reduces its own source)."""
        v_a = flight.v_kite - flight.v_wind
        V = float(np.linalg.norm(v_a))
        if V <= 0.0:
            self._downwash = None
            return 0.0
        lift_vec = sol.aero_force - (sol.aero_force @ v_a) / (V * V) * v_a  # perpendicular to the free stream
        L = float(np.linalg.norm(lift_vec))
        if L <= 0.0:
            self._downwash = None
            return 0.0
        CL = L / (0.5 * self.cfg.aero.rho_kg_m3 * V * V * self.planform_area_m2)
        alpha_i = CL / (np.pi * self.span_efficiency * self.aspect_ratio)
        old = self._downwash[0] if self._downwash is not None else 0.0
        if dt and self._downwash is not None:
            tau = 0.5 * np.sqrt(self.aspect_ratio * self.planform_area_m2) / V  # b / (2 V)
            alpha_i = old + (alpha_i - old) * (1.0 - np.exp(-dt / tau))
        self._downwash = (alpha_i, lift_vec / L)
        self._last_downwash_change = abs(alpha_i - old)
        return self._last_downwash_change

    @property
    def downwash(self) -> tuple[float, np.ndarray] | None:
        """The held downwash ``(alpha_i [rad], e_L)`` (the induced angle and the net-lift direction in K) that
        :meth:`downwashed` applies, or None (none yet, or induced drag off). Set by :meth:`update_downwash` and the
        cold solve; turned with the wing's frame by :meth:`rotate_downwash`."""
        return self._downwash

    def rotate_downwash(self, Q: np.ndarray) -> None:
        """Turn the held downwash's lift direction by the rotation ``Q`` (3, 3) (the induced angle kept): for a
        simulator that moves the wing's frame K between steps, ``e_L <- Q e_L`` with ``Q`` taking the old frame's
        components to the new one's. Nothing is held: nothing changes."""
        if self._downwash is not None:
            self._downwash = (self._downwash[0], Q @ self._downwash[1])

    def _eq3(self, dt: float | None) -> bool:
        """The paper's Eq. (3) as printed: the deformation velocity enters the section inflow."""
        return bool(dt) and self.cfg.aero.damping == "eq3"

    def _aero(self, state: NodalState, flight: FlightState, dt: float | None):
        """Section loads at ``state`` (Eq. 2-9); in a time step with ``aero.damping = "consistent"`` plus the nodal
        damping forces of :meth:`_prepare_damping`, ``f_ij = -(C_i / m) (x_ij - x_ij,prev) / dt``: each section's
        quasi-steady force response to its own translation velocity (:func:`kite_env.aero.loads.section_damping`),
        shared equally by its ``m`` nodes, each with its backward-Euler velocity in K."""
        sec = self.mesh.sections
        x = state.x[sec]
        loads = section_loads(
            x, self.mesh.section_tube_d, self.mesh.section_width, flight.v_kite, flight.omega, flight.v_wind,
            self.cfg.aero.rho_kg_m3, x_sec_prev=self._sec_prev if self._eq3(dt) else None,
            dt=dt if self._eq3(dt) else None,
            **self.aero_options())
        if dt and self._C_damp is not None:
            m = sec.shape[1]
            f_d = np.einsum("ikl,ijl->ijk", self._C_damp, x - self._sec_prev) * (-1.0 / (m * dt))
            loads = dataclasses.replace(loads, nodal_forces=loads.nodal_forces + f_d)
        return loads

    def _prepare_damping(self, flight: FlightState, dt: float | None) -> None:
        """Section damping matrices of a time step (``aero.damping = "consistent"``), at the previous committed shape
        and the step's flight state, held over the step's Newton solve (so the damping force is linear in the node
        positions and its tangent ``C / (m dt)`` exact). None for static solves and for Eq. (3)."""
        self._C_damp = None
        if dt and self.cfg.aero.damping == "consistent" and self._sec_prev is not None:
            self._C_damp = section_damping(
                self._sec_prev, self.mesh.section_tube_d, self.mesh.section_width, flight.v_kite, flight.omega,
                flight.v_wind, self.cfg.aero.rho_kg_m3, **self.aero_options())

    def load_vector(self, loads, scale: float = 1.0) -> np.ndarray:
        """The nodal load vector (n_dof,) of section loads ``loads`` (:class:`kite_env.aero.loads.SectionLoads`, its
        ``nodal_forces`` on the section nodes) times ``scale``: the forces on the translational DOF of the section
        nodes, zero elsewhere, in the DOF order of the wing's assemblers."""
        return np.bincount(self._load_dofs, weights=scale * loads.nodal_forces.ravel(), minlength=self.n_dof)

    # ------------------------------------------------------------------ main entry
    def solve(self, q_b: np.ndarray | None, flight: FlightState, dt: float | None = None, support: str = "prescribed",
              warm: bool = True, commit: bool = True, method: str = "monolithic") -> WingSolution:
        """Static aeroelastic equilibrium for bridle points ``q_b`` (4, 3) [m] in K (None: design positions).

        ``dt`` [s] enables the deformation velocity of Eq. (3) relative to the previous committed solution.
        ``warm=False`` starts from the unloaded wing with a dynamic-pressure ramp (``fsi.cold_load_steps``).
        ``commit`` stores the solution as the warm start (and Eq. 3 reference) of the next call.
        """
        if support not in ("prescribed", "lines"):
            raise ValueError(f"support must be 'prescribed' or 'lines', got {support!r}")
        if method not in ("monolithic", "staggered"):
            raise ValueError(f"method must be 'monolithic' or 'staggered', got {method!r}")
        q_b = self.design_bridle if q_b is None else np.asarray(q_b, dtype=float).reshape(4, 3)
        if not np.all(np.isfinite(q_b)):
            raise ValueError("bridle positions q_b contain non-finite values")
        t0 = time.perf_counter()
        free = flight
        if not warm:
            self._downwash = None
        flight = self.downwashed(flight)
        predicted = warm and self.state is not None and self._step_prev is not None
        if warm and self.state is not None:
            state = self._predict(dt) if predicted else self.state.copy()
            ramp = [1.0]
        else:
            state = self.unloaded_state()
            n = self.cfg.fsi.cold_load_steps
            ramp = list(np.arange(1, n + 1) / n)
        history: list[dict] = []
        sol = None
        self._prepare_damping(flight, dt)
        # large moves of the bridle points are applied in sub-steps of at most fsi.max_bridle_step_m, each one
        # converged, so that the coupling always starts close to the solution (a large jump can carry the
        # flexible tips onto a collapsed branch)
        q_start = state.x[self.bridle].copy()
        move = float(np.max(np.linalg.norm(q_b - q_start, axis=1)))
        if support == "lines":
            move = float(np.max(np.abs((q_b - q_start)[:, [0, 2]])))
        n_sub = max(1, int(np.ceil(move / self.cfg.fsi.max_bridle_step_m)))
        step = self._monolithic if method == "monolithic" else self._couple
        cold = not (warm and self.state is not None)
        # a cold solve whose load ramp fails is made again from the unloaded wing with a ramp of twice (then four
        # times) as many steps: the ramp's intermediate states depend on its steps, and on finer chordwise meshes the
        # default ramp passes through states without a stable equilibrium nearby (a sideways mode of the mid-wing's
        # leading edge fed by the loads, docs/validation.md, "Mesh refinement, L/D, the figure's elevation"); only the
        # path to the equilibrium changes
        restarts = self.COLD_RESTARTS if cold else 0
        tension0 = self.lines.tension.copy() if restarts else None
        first = None
        for restart in range(restarts + 1):
            try:
                state, sol = self._solve_path(state, q_b, q_start, n_sub, predicted, flight, dt, support, ramp, cold,
                                              step, method, history)
                break
            except WingConvergenceError as exc:
                first = first or exc
                if restart == restarts:  # the first failure (its message and cause), with every path's history
                    first.history = history
                    raise first  # noqa: B904 (the first failure itself, its own cause and traceback kept)
                n = len(ramp) * 2
                ramp = list(np.arange(1, n + 1) / n)
                # from the unloaded wing, forgetting what the failed path left in it (reset()); the committed state,
                # the step's damping and the line tensions it started with kept
                kept = (self.state, self._sec_prev, self._step_prev, self._C_damp, self._free_flight, self._downwash)
                self.reset()
                (self.state, self._sec_prev, self._step_prev, self._C_damp, self._free_flight,
                 self._downwash) = kept
                self.lines.tension[:] = tension0
                state = self.unloaded_state()
                history.append({"cold_restart": n})
        sol.history = history
        if commit:
            # time stepping (dt given, warm): remember the previous step for the linear predictor
            self._step_prev = (self.state, dt) if (dt and warm) else None
            self.state = state
            self._sec_prev = state.x[self.mesh.sections].copy()
        sol.history.append({"wall_s": time.perf_counter() - t0})
        if self.cfg.aero.induced_drag and commit:
            prev = 0.0 if self._downwash is None else self._downwash[0]
            change = self.update_downwash(sol, free, dt if warm else None)
            # cold start: iterate the induced angle to a fixed point, in under-relaxed steps of at most 1 deg (a
            # sudden 5 deg turn of the inflow would be too large a step for the wing's Newton solve)
            for _ in range(40 if not warm else 0):
                if change < 1e-4:
                    break
                alpha_i, e_L = self._downwash
                self._downwash = (prev + float(np.clip(0.5 * (alpha_i - prev), -0.0175, 0.0175)), e_L)
                prev = self._downwash[0]
                sol = self.solve(q_b, free, support=support, warm=True, method=method)
                change = abs(self._downwash[0] - prev)
        return sol

    #: cold solves whose load ramp fails are made again with a ramp of 2x, then 4x the steps (:meth:`solve`)
    COLD_RESTARTS = 2

    def _solve_path(self, state, q_b, q_start, n_sub, predicted, flight, dt, support, ramp, cold, step, method,
                    history):
        """The continuation of :meth:`solve` from ``state``: the load ramp and the C_M continuation of a cold solve,
        then the solve at full load with its retries (:meth:`_attempts`). Returns ``(state, solution)``. A failed
        path leaves no flag set; its history entries stay in ``history`` (the first guess of the line tensions of a
        monolithic solve on lines is made again: it looks for a converged entry in this path's part of it)."""
        part: list[dict] = []
        if cold and self.cfg.aero.cm_regression_ref_over_c < self.CM_CONTINUATION_START:
            self._cm_ref = self.CM_CONTINUATION_START  # the load ramp with C_M about c/4 (_cm_continuation)
        # continuation in the tube law: a cold solve of the conservative law (element_energy) follows the load ramp
        # and the C_M continuation with the larger-end law, whose secant iteration converges there, and makes its
        # last solve from that equilibrium with the exact tangent of the conservative law. On the secant alone its
        # C_M continuation stagnated (a few N above the tolerance) and the cold start of tests/dynamics/test_flight.py
        # failed (docs/model.md, "Energy", "The conservative tube law"). Only the path changes.
        if cold:
            self._tube_law = "max_end"
        try:
            try:
                if len(ramp) > 1:
                    state = self._cold_ramp(state, q_b, flight, dt, support, ramp[-2], 1.0 / len(ramp), part, step)
                if cold:
                    state = self._cm_continuation(state, q_b, flight, dt, support, ramp, part, step, method)
            finally:
                self._cm_ref = None
                self._tube_law = None
            start = state
            self._exact_tube_tangent = cold
            try:
                return self._attempts(start, q_start, q_b, n_sub, predicted, flight, dt, support, ramp[-1], part,
                                      step, method)
            finally:
                self._damped = False
                self._exact_tube_tangent = False
        finally:
            history.extend(part)

    def _attempts(self, start, q_start, q_b, n_sub, predicted, flight, dt, support, scale, history, step, method):
        """The solve of :meth:`solve` with its retries: from the last solution (not the predicted start) with a fresh
        factorisation, then with the Levenberg-Marquardt-damped Newton, then with twice as many bridle sub-steps."""
        for attempt in range(self.cfg.fsi.max_retries + 1):
            try:
                state = start
                for k in range(1, n_sub + 1):
                    q_k = q_start + (q_b - q_start) * (k / n_sub)
                    state, sol = step(state, q_k, flight, dt, support, scale, history)
                return state, sol
            except WingConvergenceError:
                if attempt == self.cfg.fsi.max_retries:
                    raise
                for solver in self._mono_solvers.values():
                    solver.forget_factorization()
                if predicted:
                    predicted = False
                    start = self.state.copy()
                elif method == "monolithic" and not self._damped:
                    self._damped = True
                else:
                    n_sub *= 2
                history.append({"retry": attempt + 1, "n_sub": n_sub, "damped": self._damped})

    def _monolithic(self, state, q_b, flight, dt, support, scale, history):
        """Newton on the coupled residual ``F_a(x) - f_int(x) = 0`` with the aero load Jacobian in the tangent.

        With ``support="lines"`` the bridle-line tensions are held fixed in a Newton solve and updated from the
        reactions between solves, until they change by less than ``fsi.tol_force_rel``.
        """
        fcfg = self.cfg.fsi
        b = self.bridle
        solver = self._mono_solvers[support]
        fixed, du_fixed = self._support(state, q_b, support)
        n_outer = 1 if support == "prescribed" else fcfg.max_coupling_iter
        load = _AeroLoad(self, solver.asm, flight, dt, scale)
        if support == "lines" and not any("method" in h for h in history):  # before the first converged solve
            # first guess of the line tensions: the aerodynamic force shared by the four lines
            f0 = load.force(state).reshape(-1, 6)[:, :3].sum(axis=0)
            self.lines.tension[:] = max(float(np.linalg.norm(f0)) / 4.0, 1.0)
        for _outer in range(1, n_outer + 1):
            try:
                if self._damped:
                    res = solver.solve_damped(state, fixed, du_fixed, load, fcfg.tol_force_rel, fcfg.tol_disp_m,
                                              max_iter=2 * fcfg.max_newton_iter, accept_force=fcfg.accept_force_rel)
                else:
                    res = solver.solve(state, None, fixed, du_fixed, load=load, tol_force=fcfg.tol_force_rel,
                                       tol_disp=fcfg.tol_disp_m, accept_force=fcfg.accept_force_rel)
            except ConvergenceError as exc:
                history.append({"iter": len(history) + 1, "dx_max_m": np.nan, "dload_rel": np.nan,
                                "newton_iters": len(exc.history), "residual_history": exc.history})
                raise WingConvergenceError(f"monolithic aeroelastic Newton solve failed: {exc}", history) from exc
            state = res.state
            du_fixed = np.zeros_like(du_fixed)
            if res.accepted:  # the best iterate, not the last one: loads at that state
                load.force(state)
            f_ext = load.f_ext  # aero loads at the returned state
            fi_b = (res.reactions + f_ext).reshape(-1, 6)[b, :3]  # wing + line internal force at A-D
            entry = {"iter": len(history) + 1, "dx_max_m": res.history[-2][2] if len(res.history) > 1 else 0.0,
                     "dload_rel": 0.0, "newton_iters": res.iterations, "scale": scale, "method": "monolithic",
                     "residual_N": res.history[-1][1], "factorizations": res.factorizations,
                     "jacobians": load.n_tangent, "accepted": res.accepted}
            history.append(entry)
            if support == "prescribed":
                break
            fi_b = self._without_lines(state, fi_b)
            entry["dT_rel"] = self._update_line_tensions(state, fi_b - f_ext.reshape(-1, 6)[b, :3])
            if entry["dT_rel"] < fcfg.tol_force_rel:
                break
        else:
            raise WingConvergenceError(
                f"bridle-line tensions did not converge in {n_outer} monolithic solves "
                f"(tol_force_rel={fcfg.tol_force_rel})", history)
        newton = sum(h.get("newton_iters", 0) for h in history if "iter" in h)
        return state, self._solution(state, load.loads, fi_b - f_ext.reshape(-1, 6)[b, :3], flight, scale, history,
                                     newton, load.collapsed, any(h.get("accepted", False) for h in history))

    def _couple(self, state, q_b, flight, dt, support, scale, history):
        fcfg = self.cfg.fsi
        b = self.bridle
        fixed, du_fixed = self._support(state, q_b, support)
        solver = self.solver if support == "prescribed" else self._lines_solver
        f_prev = None
        newton_total = 0
        collapsed = None
        f_used = None  # relaxed load vector applied to the structure
        r_prev = None
        omega = fcfg.relax_initial
        for it in range(1, fcfg.max_coupling_iter + 1):
            loads = self._aero(state, flight, dt)
            f_aero = self.load_vector(loads, scale)
            # Aitken's dynamic under-relaxation of the aerodynamic load vector (Irons & Tuck 1969; Kuettler & Wall
            # 2008): the plain alternation of Fig. 2 diverges for this very flexible wing, whose section angles of
            # attack, and so its loads, follow the shape strongly. The fixed point (the equilibrium) is unchanged.
            if f_used is None:
                f_ext = f_aero
            else:
                r_k = f_aero - f_used
                if r_prev is not None:
                    dr = r_k - r_prev
                    den = float(dr @ dr)
                    if den > 0.0:
                        omega = float(np.clip(-omega * float(r_prev @ dr) / den, fcfg.relax_min, 1.0))
                f_ext = f_used + omega * r_k
                r_prev = r_k
            f_used = f_ext
            if support == "lines" and it == 1:
                # first guess of the line tensions: the aerodynamic force shared by the four lines
                self.lines.tension[:] = max(np.linalg.norm(f_ext.reshape(-1, 6)[:, :3].sum(axis=0)) / 4.0, 1.0)
            fnorm = np.linalg.norm(f_aero)
            dload = np.inf if f_prev is None else np.linalg.norm(f_aero - f_prev) / max(fnorm, 1e-12)
            collapsed = self.update_tube_stiffness(state, material_tangent=False)
            try:
                # inexact inner solve: a few Newton steps per load update (the loads are relaxed and updated
                # anyway); the coupling only ends on an inner solve that converged to the Newton tolerance
                res = solver.solve(state, f_ext, fixed, du_fixed, max_iter=fcfg.newton_per_coupling,
                                   allow_partial=True)
            except ConvergenceError as exc:
                history.append({"iter": it, "dx_max_m": np.nan, "dload_rel": dload, "newton_iters": -1})
                raise WingConvergenceError(f"structural Newton solve failed in coupling iteration {it}: {exc}",
                                           history) from exc
            dxn = np.max(np.abs(res.state.x - state.x), axis=1)
            dx = float(dxn.max())
            state = res.state
            du_fixed = np.zeros_like(du_fixed)
            newton_total += res.iterations
            entry = {"iter": it, "dx_max_m": dx, "dload_rel": dload, "newton_iters": res.iterations, "scale": scale,
                     "relax": omega, "newton_converged": res.converged, "residual_N": res.history[-1][1],
                     "dx_node": int(np.argmax(dxn))}
            # wing internal force at A-D from the solver's reactions (f_int - f_ext at the returned state), without
            # the bridle-line elements: no extra assembly
            fi_b = (res.reactions + f_ext).reshape(-1, 6)[b, :3]
            if support == "lines":
                fi_b = self._without_lines(state, fi_b)
                entry["dT_rel"] = self._update_line_tensions(state, fi_b - f_ext.reshape(-1, 6)[b, :3])
            history.append(entry)
            if not np.isfinite(dx):
                raise WingConvergenceError("non-finite displacement in the coupling loop", history)
            if (res.converged and dx < fcfg.tol_disp_m and dload < fcfg.tol_force_rel
                    and entry.get("dT_rel", 0.0) < fcfg.tol_force_rel):
                break
            f_prev = f_aero
        else:
            raise WingConvergenceError(
                f"static aeroelastic coupling did not converge in {fcfg.max_coupling_iter} iterations "
                f"(tol_disp_m={fcfg.tol_disp_m}, tol_force_rel={fcfg.tol_force_rel})", history)
        # final aero loads on the converged shape and reactions F_b (second block of Eq. 1)
        loads = self._aero(state, flight, dt)
        f_ext = self.load_vector(loads, scale)
        return state, self._solution(state, loads, fi_b - f_ext.reshape(-1, 6)[b, :3], flight, scale, history,
                                     newton_total, collapsed)

    # ------------------------------------------------------------------ shared by both couplings
    def _support(self, state, q_b, support):
        """Prescribed DOF and their increments from ``state``: all translations of A-D (``"prescribed"``) or only
        their x_k and z_k (``"lines"``, which also places the line anchor at the KCU)."""
        b = self.bridle
        comp = np.arange(3) if support == "prescribed" else np.array([0, 2])
        if support == "lines":
            self.lines.anchor[:] = self.kcu_position()
        return (6 * b[:, None] + comp[None, :]).ravel(), (q_b - state.x[b])[:, comp].ravel()

    def _without_lines(self, state, fi_b):
        """Internal force at A-D (4, 3) without the bridle-line elements of ``support="lines"``."""
        return fi_b - self.lines.internal(state.x[self.bridle][:, None, :], None, tangent=False)[0][:, :3]

    def _update_line_tensions(self, state, F_b) -> float:
        """Line tension T = pull of the wing along its line (Eq. 1, second block, projected on the line); sets the
        new tensions and returns their largest change relative to the largest tension."""
        e_in = self.lines.anchor - state.x[self.bridle]
        e_in /= np.linalg.norm(e_in, axis=1, keepdims=True)
        T_new = np.maximum(np.einsum("ij,ij->i", F_b, e_in), 1.0)
        d_rel = float(np.max(np.abs(T_new - self.lines.tension)) / max(np.max(T_new), 1e-9))
        self.lines.tension[:] = T_new
        return d_rel

    def solution(self, state: NodalState, loads, F_b: np.ndarray, flight: FlightState, history: list[dict],
                 newton_iters: int, collapsed: np.ndarray | None, accepted: bool = False) -> WingSolution:
        """The :class:`WingSolution` of a shape solved outside :meth:`solve` (the wing with inertia,
        :mod:`kite_env.dynamics.wing_dynamics`): ``state`` the shape, ``loads`` its section loads at full scale,
        ``F_b`` (4, 3) the force on the wing at A-D, ``flight`` the free flight state (without the downwash) about
        whose apparent wind lift and drag are taken (kept as the wing's free flight state, as :meth:`downwashed`
        keeps it), ``history`` the solve's entries, ``newton_iters``, the tubes' ``collapsed`` flags and whether the
        Newton solve ``accepted`` its best iterate."""
        self._free_flight = flight
        return self._solution(state, loads, F_b, flight, 1.0, history, newton_iters, collapsed, accepted)

    def _solution(self, state, loads, F_b, flight, scale, history, newton_iters, collapsed, accepted=False):
        """WingSolution of a converged shape; ``F_b = F_i^b - F_a^b`` (Eq. 1, second block)."""
        free = self._free_flight if self._free_flight is not None else flight
        tot = wing_totals(loads, free.v_kite - free.v_wind)  # lift and drag about the free stream (induced drag)
        return WingSolution(
            F_b=F_b, nodes=state.x.copy(), alpha=loads.alpha, CL=loads.CL, CD=loads.CD, CM=loads.CM,
            aero_force=scale * tot["force"], lift=scale * tot["lift"], drag=scale * tot["drag"],
            coupling_iters=sum(1 for h in history if "iter" in h), newton_iters=newton_iters, accepted=accepted,
            tube_collapsed=collapsed, section_forces=scale * loads.nodal_forces,
            section_lift=scale * np.linalg.norm(loads.lift_local, axis=1),
            section_drag=scale * np.linalg.norm(loads.drag_local, axis=1), aero_moment=scale * tot["moment"],
        )


class BridleLines:
    """Bridle lines of constant tension pulling nodes towards a fixed anchor (the KCU), as an element set.

    Strain energy ``U = T |x - anchor|`` (tension held fixed within a Newton solve): internal force ``T e`` with
    ``e = (x - anchor)/|x - anchor|`` and tangent ``T/l (I - e e^T)``. Used by ``support="lines"`` only, where it
    supplies the lateral stiffness of the otherwise free ``y_k`` coordinates of A-D.
    """

    n_en = 1

    def __init__(self, nodes: np.ndarray):
        self.conn = np.asarray(nodes, dtype=np.int64).reshape(-1, 1)
        self.anchor = np.zeros((len(self.conn), 3))
        self.tension = np.ones(len(self.conn))

    def internal(self, x_e, R_e, tangent: bool = True):
        d = x_e[:, 0] - self.anchor
        l = np.linalg.norm(d, axis=1)
        e = d / l[:, None]
        n = len(l)
        f = np.zeros((n, 6))
        f[:, :3] = self.tension[:, None] * e
        if not tangent:
            return f, None
        K = np.zeros((n, 6, 6))
        K[:, :3, :3] = (self.tension / l)[:, None, None] * (np.eye(3) - e[:, :, None] * e[:, None, :])
        return f, K


class _AeroLoad:
    """Aerodynamic loads as a function of the iterate, for the monolithic Newton solve (``StaticSolver(load=...)``).

    ``force`` updates the inflated-tube secant stiffness and returns the nodal aero load vector (Eq. 2-9);
    ``tangent`` returns ``-d F_a / d x`` (section blocks, :func:`kite_env.aero.loads.load_jacobian`) on the
    assembler's pattern.
    """

    def __init__(self, wing: AeroelasticWing, asm: Assembler, flight: FlightState, dt: float | None,
                 scale: float):
        self.wing, self.asm, self.flight, self.dt, self.scale = wing, asm, flight, dt, scale
        self.f_ext = None
        # factorisations of the coupled tangent are reused across calls of the same kind only: static or time step
        # (the deformation-velocity term scales with 1/dt; dt in 25 % buckets) and load scale
        self.tangent_key = (round(scale, 6), None if not dt else int(round(np.log(dt) / np.log(1.25))))
        self.loads = None
        self.collapsed = None
        self.n_force = 0
        self.n_tangent = 0

    def force(self, state: NodalState) -> np.ndarray:
        # the tubes' exact tangent (the conservative law, element_energy) in time steps (warm starts, small
        # increments: quadratic convergence, 1.79 instead of 1.97 Newton iterations per step over the quasi-static
        # baseline); a cold static solve keeps the secant stiffness alone, Kachanov's secant iteration, which
        # converges from far for a monotone law (Kachanov, J. Appl. Math. Mech. 23, 880, 1959; Fucik, Kratochvil &
        # Necas, Comment. Math. Univ. Carolinae 14, 651, 1973): with the exact, nearly singular tangent of saturating
        # tubes a randomized start at 9 m/s (seed 100 of kite-eval end-reasons) failed that converges with the
        # secant
        self.collapsed = self.wing.update_tube_stiffness(state, material_tangent=bool(self.dt)
                                                         or self.wing._exact_tube_tangent)
        self.loads = self.wing._aero(state, self.flight, self.dt)
        self.n_force += 1
        self.f_ext = self.wing.load_vector(self.loads, self.scale)
        return self.f_ext

    def tangent(self, state: NodalState) -> np.ndarray:
        w, fl = self.wing, self.flight
        eq3 = w._eq3(self.dt)
        _, J = load_jacobian(
            state.x[w.mesh.sections], w.mesh.section_tube_d, w.mesh.section_width, fl.v_kite, fl.omega, fl.v_wind,
            w.cfg.aero.rho_kg_m3, x_sec_prev=w._sec_prev if eq3 else None, dt=self.dt if eq3 else None,
            **w.aero_options())
        if self.dt and w._C_damp is not None:
            # nodal damping forces -(C_i / m) (x_ij - x_ij,prev) / dt: a block -C_i / (m dt) on each node's diagonal
            n_sec, m = w.mesh.sections.shape
            Jr = J.reshape(n_sec, m, 3, m, 3)
            idx = np.arange(m)
            Jr[:, idx, :, idx, :] -= (w._C_damp / (m * self.dt))[None, :, :, :]
        self.n_tangent += 1
        return self.asm.block_data(-self.scale * J)


def nominal_wing(kite: str = "rhino16", cfg: Config | None = None) -> AeroelasticWing:
    """The aeroelastic wing of a named kite with the configured mesh resolution."""
    from kite_env.geometry import build_kite

    cfg = cfg or Config()
    mesh = build_kite(kite, n_sections=cfg.kite.n_sections, n_chord=cfg.kite.n_chord)
    return AeroelasticWing(mesh, cfg)
