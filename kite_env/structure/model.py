"""Stand-alone static finite-element model for verification problems: beams, inflated tubes and shells.

:class:`FEModel` wraps the element sets (:class:`~kite_env.structure.beam.BeamSet`,
:class:`~kite_env.structure.shell.ShellSet`), the :class:`~kite_env.structure.assembly.Assembler` and the
Newton-Raphson :class:`~kite_env.structure.solver.StaticSolver` behind a small API, so that a structural problem can
be posed without the kite mesh or the aerodynamics::

    import numpy as np
    from kite_env.structure.model import FEModel

    n = 16                                                   # cantilever, L = 1 m, EI = 1 N m^2
    m = FEModel(np.c_[np.linspace(0.0, 1.0, n + 1), np.zeros(n + 1), np.zeros(n + 1)])
    m.add_beams(np.c_[np.arange(n), np.arange(1, n + 1)], up=(0, 0, 1), EA=1e6, EI2=1.0, EI3=1.0, GJ=1.0)
    m.fix(0)                                                 # clamp node 0 (all six DOF)
    m.add_load(n, force=(0.0, 0.0, -1.0))                    # P L^2 / EI = 1
    res = m.solve(load_steps=2)
    res.displacements[-1]                                    # ~ (-0.0564, 0, -0.3017): the elastica

Conventions: 6 DOF per node ``[u_x, u_y, u_z, w_x, w_y, w_z]`` in one global frame;
rotations are spatial spins (``R <- expm(dw) R``); SI units. Loads are applied in ``load_steps`` equal increments
(prescribed displacements too), each step solved to equilibrium by Newton-Raphson.

Two effects are handled by fixed-point (outer) iterations inside each load step, because the Newton solver holds
the external loads and the section stiffness fixed:

* follower pressure (:meth:`FEModel.add_pressure` with ``follower=True``): the nodal loads are recomputed on the
  converged shape and the step is re-solved until they stop changing (no load stiffness in the tangent, so the
  outer iteration converges only while the pressure load stiffness is small compared with the structure's);
* the secant Breukels tube law (:meth:`FEModel.add_inflated_tubes` with ``tube_law="secant"``): the tube ``EI`` and
  ``GJ`` are replaced by the secant stiffness of the current curvature and twist (:mod:`kite_env.structure.tube`)
  until they stop changing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import tube
from .assembly import DOF_PER_NODE, Assembler
from .beam import BeamSet
from .rotations import logm
from .solver import ConvergenceError, NodalState, StaticSolver

#: Names of the six nodal DOF, in order.
DOF_NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")
_DOF_GROUPS = {"all": (0, 1, 2, 3, 4, 5), "xyz": (0, 1, 2), "rxryrz": (3, 4, 5)}


# ------------------------------------------------------------------------------------------------ sections
@dataclass(frozen=True)
class CircularRod:
    """Solid circular section of ``diameter`` [m]: ``A = pi d^2 / 4``, ``I = pi d^4 / 64``, ``J = 2 I``."""

    diameter: float

    @property
    def area(self) -> float:
        return np.pi * self.diameter**2 / 4.0

    @property
    def inertia(self) -> float:
        return np.pi * self.diameter**4 / 64.0

    @property
    def polar(self) -> float:
        return 2.0 * self.inertia


@dataclass(frozen=True)
class CircularTube:
    """Thin- or thick-walled circular tube of outer ``diameter`` [m] and ``wall`` thickness [m] (``J = 2 I``)."""

    diameter: float
    wall: float

    @property
    def area(self) -> float:
        di = self.diameter - 2.0 * self.wall
        return np.pi * (self.diameter**2 - di**2) / 4.0

    @property
    def inertia(self) -> float:
        di = self.diameter - 2.0 * self.wall
        return np.pi * (self.diameter**4 - di**4) / 64.0

    @property
    def polar(self) -> float:
        return 2.0 * self.inertia


# ------------------------------------------------------------------------------------------------ result
@dataclass
class FEResult:
    """Converged static solution of an :class:`FEModel` (failures raise instead).

    Attributes
    ----------
    positions : (n_nodes, 3) float [m]      deformed node positions.
    displacements : (n_nodes, 3) float [m]  ``positions - nodes``.
    rotations : (n_nodes, 3, 3) float       nodal rotation matrices (identity = unrotated).
    reactions : (n_nodes, 6) float [N, N m] force and moment the supports apply to the structure at fixed and
        prescribed DOF (zero elsewhere); with the external loads they balance: sum of reaction forces + sum of
        applied forces = 0.
    iterations : int                        Newton iterations summed over all load steps and outer iterations.
    history : list of dict                  per load step: ``step``, ``load_factor``, ``outer`` (outer iterations),
        ``iterations`` and ``residuals`` (Newton residual norms of every solve of the step).
    info : dict                             ``tube_collapsed`` (n_tube_elements,) bool when tubes are present.
    """

    positions: np.ndarray
    displacements: np.ndarray
    rotations: np.ndarray
    reactions: np.ndarray
    iterations: int
    history: list = field(default_factory=list)
    info: dict = field(default_factory=dict)

    @property
    def rotation_vectors(self) -> np.ndarray:
        """Nodal rotation vectors ``logm(rotations)`` (n_nodes, 3) [rad], ``|theta| <= pi``."""
        return logm(self.rotations)


# ------------------------------------------------------------------------------------------------ model
class FEModel:
    """Static FE model on nodes with 6 DOF each.

    Parameters
    ----------
    nodes : (n_nodes, 3) float [m]
        Reference (unloaded) node coordinates.
    """

    def __init__(self, nodes):
        nodes = np.array(nodes, dtype=float)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or nodes.shape[0] < 2:
            raise ValueError(f"FEModel: nodes must have shape (n_nodes >= 2, 3), got {nodes.shape}")
        if not np.all(np.isfinite(nodes)):
            raise ValueError("FEModel: nodes contain non-finite coordinates")
        self.nodes = nodes
        self.sets: list = []
        self._tubes: list = []  # (BeamSet, TubeProperties, secant: bool)
        self._constraints: dict = {}  # global DOF -> prescribed value [m or rad]
        self._loads = np.zeros((self.n_nodes, 6))
        self._pressures: list = []  # (tris (m, 3), p (m,), follower)

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    # -------------------------------------------------------------------------------------------- checks
    def _node_array(self, nodes, what: str) -> np.ndarray:
        arr = np.asarray(nodes)
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"{what}: node indices must be integers, got dtype {arr.dtype}")
        arr = arr.astype(np.int64)
        if arr.size and (arr.min() < 0 or arr.max() >= self.n_nodes):
            bad = arr[(arr < 0) | (arr >= self.n_nodes)]
            raise ValueError(f"{what}: node index {int(bad.flat[0])} outside 0..{self.n_nodes - 1}")
        return arr

    def _conn(self, conn, n_en: int, what: str) -> np.ndarray:
        c = self._node_array(conn, what)
        if c.ndim != 2 or c.shape[1] != n_en or c.shape[0] == 0:
            raise ValueError(f"{what}: connectivity must have shape (n_elem >= 1, {n_en}), got {c.shape}")
        s = np.sort(c, axis=1)
        if np.any(s[:, 1:] == s[:, :-1]):
            raise ValueError(f"{what}: element(s) {np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], 1))[:5]} repeat a node")
        return c

    @staticmethod
    def _positive(what: str, name: str, val, n: int) -> np.ndarray:
        arr = np.asarray(val, dtype=float)
        try:
            arr = np.array(np.broadcast_to(arr, (n,)))
        except ValueError:
            raise ValueError(f"{what}: {name} must be a scalar or have shape ({n},), got {arr.shape}") from None
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
            raise ValueError(f"{what}: {name} must be finite and positive (min {np.min(arr):g})")
        return arr

    @staticmethod
    def _vec3(what: str, val, n: int) -> np.ndarray:
        arr = np.asarray(val, dtype=float)
        if arr.shape not in ((3,), (n, 3)):
            raise ValueError(f"{what}: expected shape (3,) or ({n}, 3), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{what}: contains non-finite values")
        return np.array(np.broadcast_to(arr, (n, 3)))

    @staticmethod
    def _dofs(dofs) -> tuple:
        if isinstance(dofs, str):
            if dofs in _DOF_GROUPS:
                return _DOF_GROUPS[dofs]
            dofs = [dofs]
        out = []
        for d in np.atleast_1d(np.asarray(dofs, dtype=object)):
            if isinstance(d, str) and d in DOF_NAMES:
                out.append(DOF_NAMES.index(d))
            elif isinstance(d, (int, np.integer)) and 0 <= int(d) < DOF_PER_NODE:
                out.append(int(d))
            else:
                raise ValueError(f"unknown DOF {d!r}: use 0..5, one of {DOF_NAMES} or a group {tuple(_DOF_GROUPS)}")
        return tuple(out)

    # -------------------------------------------------------------------------------------------- elements
    def add_beams(self, conn, up, EA=None, EI2=None, EI3=None, GJ=None, *, section=None, E=None, nu=None,
                  G=None) -> BeamSet:
        """Add co-rotational Euler-Bernoulli beams (:class:`~kite_env.structure.beam.BeamSet`).

        Give either the four section stiffnesses, or a ``section`` (:class:`CircularRod`, :class:`CircularTube`
        or any object with ``area``, ``inertia``, ``polar``) with Young's modulus ``E`` and ``nu`` (or ``G``).

        Parameters
        ----------
        conn : (n_e, 2) int              node indices.
        up : (3,) or (n_e, 3) float      vector fixing the local y axis (not parallel to the beam).
        EA : float or (n_e,) [N]         axial stiffness.
        EI2, EI3 : float or (n_e,) [N m^2]  bending stiffness about the local y (``up``) and z axes.
        GJ : float or (n_e,) [N m^2]     torsion stiffness.
        section : object                 ``area`` [m^2], ``inertia`` [m^4] (both axes), ``polar`` [m^4].
        E : float [Pa]; nu : float [-]; G : float [Pa] (default ``E / (2 (1 + nu))``).

        Returns
        -------
        BeamSet (kept in :attr:`sets`).
        """
        what = "add_beams"
        conn = self._conn(conn, 2, what)
        n_e = conn.shape[0]
        explicit = [v is not None for v in (EA, EI2, EI3, GJ)]
        if section is not None:
            if any(explicit):
                raise ValueError(f"{what}: give either section (+ E, nu) or EA, EI2, EI3, GJ, not both")
            if E is None or (nu is None and G is None):
                raise ValueError(f"{what}: a section needs E and nu (or G)")
            E = self._positive(what, "E", E, n_e)
            if G is None:
                if not -1.0 < float(nu) < 0.5:
                    raise ValueError(f"{what}: nu must be in (-1, 0.5), got {nu}")
                G = E / (2.0 * (1.0 + float(nu)))
            G = self._positive(what, "G", G, n_e)
            A, I, J = (self._positive(what, f"section.{k}", getattr(section, k), n_e)
                       for k in ("area", "inertia", "polar"))
            EA, EI2, EI3, GJ = E * A, E * I, E * I, G * J
        elif not all(explicit):
            raise ValueError(f"{what}: EA, EI2, EI3 and GJ are all required (or a section with E, nu)")
        stiff = {k: self._positive(what, k, v, n_e) for k, v in (("EA", EA), ("EI2", EI2), ("EI3", EI3), ("GJ", GJ))}
        bs = BeamSet(conn, self.nodes, self._vec3(f"{what}: up", up, n_e), **stiff)
        self.sets.append(bs)
        return bs

    def add_inflated_tubes(self, conn, up, diameter_m, pressure_pa, wall_Et, *, tube_law: str = "initial") -> BeamSet:
        """Add inflated tubes: beams whose bending and torsion stiffness follow Breukels' correlations.

        ``EI`` and ``GJ`` are the initial stiffness ``EI0(p, d)`` and ``GJ0(p, d)`` of
        :func:`kite_env.structure.tube.tube_properties`; with ``tube_law="secant"`` they are replaced in every load
        step by the secant stiffness of the current curvature and twist (Breukels' nonlinear moment-curvature and
        torque-twist laws, fixed-point iteration, see the module docstring). The axial stiffness is that of the
        fabric wall, ``EA = wall_Et * pi * d``.

        Parameters
        ----------
        conn : (n_e, 2) int; up : (3,) or (n_e, 3) float    as in :meth:`add_beams`.
        diameter_m : float or (n_e,) [m]     tube diameter.
        pressure_pa : float [Pa]             inflation (gauge) pressure.
        wall_Et : float or (n_e,) [N/m]      membrane stiffness of the wall (Young's modulus x wall thickness).
        tube_law : "initial" | "secant"
        """
        what = "add_inflated_tubes"
        if tube_law not in ("initial", "secant"):
            raise ValueError(f"{what}: tube_law must be 'initial' or 'secant', got {tube_law!r}")
        conn = self._conn(conn, 2, what)
        n_e = conn.shape[0]
        d = self._positive(what, "diameter_m", diameter_m, n_e)
        Et = self._positive(what, "wall_Et", wall_Et, n_e)
        p = float(pressure_pa)
        if not np.isfinite(p) or p <= 0.0:
            raise ValueError(f"{what}: pressure_pa must be finite and positive, got {pressure_pa}")
        props = tube.tube_properties(p, d)  # raises where Breukels' fits are non-physical
        bs = BeamSet(conn, self.nodes, self._vec3(f"{what}: up", up, n_e), EA=Et * np.pi * d,
                     EI2=props.EI0, EI3=props.EI0, GJ=props.GJ0)
        self.sets.append(bs)
        self._tubes.append((bs, props, tube_law == "secant"))
        return bs

    def add_shells(self, conn, E, nu, h, wrinkling: bool = True, **shell_kwargs):
        """Add flat shell triangles (:class:`kite_env.structure.shell.ShellSet`, imported on first use).

        Parameters
        ----------
        conn : (n_e, 3) int      triangle node indices.
        E : float [Pa]; nu : float [-]; h : float [m]   fabric modulus, Poisson ratio, thickness.
        wrinkling : bool         tension-field (wrinkling) membrane law.
        **shell_kwargs           passed on to ``ShellSet`` (e.g. ``eps_slack``, ``drill_factor``, ``bending``).
        """
        from .shell import ShellSet  # lazy: beams work without the shell module

        what = "add_shells"
        conn = self._conn(conn, 3, what)
        n_e = conn.shape[0]
        E = self._positive(what, "E", E, n_e)
        h = self._positive(what, "h", h, n_e)
        nu_arr = np.array(np.broadcast_to(np.asarray(nu, dtype=float), (n_e,)))
        if not np.all((nu_arr > -1.0) & (nu_arr < 0.5)):
            raise ValueError(f"{what}: nu must be in (-1, 0.5)")
        ss = ShellSet(conn, self.nodes, E=E, nu=nu_arr, h=h, wrinkling=wrinkling, **shell_kwargs)
        self.sets.append(ss)
        return ss

    # -------------------------------------------------------------------------------------------- boundary conditions
    def fix(self, nodes, dofs="all") -> None:
        """Hold DOF at zero displacement / rotation.

        Parameters
        ----------
        nodes : int or array of int
        dofs : "all" | "xyz" | "rxryrz" | list of 0..5 or names ``"ux", "uy", "uz", "rx", "ry", "rz"``.
            A later :meth:`prescribe` of the same DOF replaces the zero (and vice versa).
        """
        nodes = np.atleast_1d(self._node_array(nodes, "fix")).ravel()
        for k in self._dofs(dofs):
            for nd in nodes:
                self._constraints[DOF_PER_NODE * int(nd) + k] = 0.0

    def prescribe(self, node, dof, value) -> None:
        """Prescribe a displacement [m] (``ux, uy, uz``) or a rotation [rad] (``rx, ry, rz``) of one node.

        The value is reached in ``load_steps`` equal increments. A prescribed rotation component is the accumulated
        spin about that global axis: exact when it is the node's only rotation or all three are prescribed together.
        """
        node = self._node_array(node, "prescribe")
        if node.ndim != 0:
            raise ValueError("prescribe: give one node index")
        ks = self._dofs(dof)
        if len(ks) != 1:
            raise ValueError(f"prescribe: give one DOF, got {dof!r}")
        k = ks[0]
        value = float(value)
        if not np.isfinite(value):
            raise ValueError(f"prescribe: value must be finite, got {value}")
        self._constraints[DOF_PER_NODE * int(node) + k] = value

    # -------------------------------------------------------------------------------------------- loads
    def add_load(self, node, force=None, moment=None) -> None:
        """Add dead nodal loads (accumulated over calls).

        Parameters
        ----------
        node : int or (k,) int
        force : (3,) or (k, 3) float [N]
        moment : (3,) or (k, 3) float [N m]   about the global axes.
        """
        nodes = np.atleast_1d(self._node_array(node, "add_load"))
        if nodes.ndim != 1:
            raise ValueError("add_load: node must be an index or a 1-D array of indices")
        if force is None and moment is None:
            raise ValueError("add_load: give a force and/or a moment")
        if force is not None:
            np.add.at(self._loads[:, :3], nodes, self._vec3("add_load: force", force, nodes.size))
        if moment is not None:
            np.add.at(self._loads[:, 3:], nodes, self._vec3("add_load: moment", moment, nodes.size))

    def add_pressure(self, tris="all", p=0.0, follower: bool = False) -> None:
        """Add a uniform pressure on triangles: force ``p A n`` per triangle, a third to each of its nodes.

        ``n`` is the unit normal along ``(x1 - x0) x (x2 - x0)``; ``p > 0`` pushes along ``n``. The triangles need not
        be shell elements. ``follower=False``: dead loads from the reference geometry; ``follower=True``: recomputed
        on the deformed geometry by outer iterations in every load step (see the module docstring).

        Parameters
        ----------
        tris : (m, 3) int or "all"     triangles; "all": the triangles of every shell set added so far.
        p : float or (m,) float [Pa]
        follower : bool
        """
        if isinstance(tris, str):
            if tris != "all":
                raise ValueError(f"add_pressure: tris must be an (m, 3) int array or 'all', got {tris!r}")
            shells = [s.conn for s in self.sets if np.asarray(s.conn).shape[1] == 3]
            if not shells:
                raise ValueError("add_pressure: 'all' needs shells; none added yet")
            tris = np.concatenate(shells)
        tris = self._conn(tris, 3, "add_pressure")
        p_arr = np.asarray(p, dtype=float)
        if p_arr.shape not in ((), (tris.shape[0],)) or not np.all(np.isfinite(p_arr)):
            raise ValueError(f"add_pressure: p must be finite, scalar or ({tris.shape[0]},), got shape {p_arr.shape}")
        self._pressures.append((tris, np.array(np.broadcast_to(p_arr, (tris.shape[0],))), bool(follower)))

    def pressure_loads(self, x=None, follower=None) -> np.ndarray:
        """Nodal loads (n_nodes, 6) [N] of the pressure patches on positions ``x`` (default: reference nodes).

        ``follower``: None all patches, True/False only follower / dead patches.
        """
        x = self.nodes if x is None else np.asarray(x, dtype=float)
        f = np.zeros((self.n_nodes, 6))
        for tris, p, fol in self._pressures:
            if follower is not None and fol != follower:
                continue
            xe = x[tris]
            fe = (p / 6.0)[:, None] * np.cross(xe[:, 1] - xe[:, 0], xe[:, 2] - xe[:, 0])  # |cross| = 2 A
            for k in range(3):
                f[:, k] += np.bincount(tris.ravel(), weights=np.repeat(fe[:, k], 3), minlength=self.n_nodes)
        return f

    # -------------------------------------------------------------------------------------------- solve
    @staticmethod
    def _tube_strains(bs: BeamSet, state: NodalState):
        """Curvature [1/m] and twist rate [rad/m] of tube elements for the secant law, each (n_e,): the larger end
        curvature of the cubic element (:func:`kite_env.structure.tube.element_curvature`, the law of the cold solve's
        continuation in fsi.py)."""
        loc = bs.local_deformation(state.x[bs.conn], state.Rn[bs.conn])
        th1, th2, L0 = loc["theta1"], loc["theta2"], loc["L0"]
        return tube.element_curvature(th1, th2, L0, "max_end"), np.abs(th2[:, 0] - th1[:, 0]) / L0

    def _update_tubes(self, state: NodalState) -> float:
        """Secant tube stiffness from the current shape; returns the largest relative stiffness change."""
        change = 0.0
        for bs, props, secant in self._tubes:
            if not secant:
                continue
            kappa, phi = self._tube_strains(bs, state)
            EI, GJ = tube.secant_EI(props, kappa), tube.secant_GJ(props, phi)
            change = max(change, float(np.max(np.abs(EI / bs.EI2 - 1.0))), float(np.max(np.abs(GJ / bs.GJ - 1.0))))
            # held over the next Newton solve (a linear law there): no material tangent terms
            bs.set_bending_torsion(np.arange(bs.n_elem), EI, GJ)
        return change

    def solve(self, load_steps: int = 10, *, mode: str = "full", tol_force: float = 1e-8, max_iter: int = 40,
              max_rot_rad: float = 0.5, outer_tol: float = 1e-8, max_outer: int = 200) -> FEResult:
        """Static equilibrium under the loads and prescribed DOF, applied in ``load_steps`` equal increments.

        Every call starts from the unloaded reference state (tube stiffness reset to ``EI0``, ``GJ0``).

        Parameters
        ----------
        load_steps : int               number of equal load / prescribed-displacement increments.
        mode : "full" | "modified"     Newton variant of :class:`~kite_env.structure.solver.StaticSolver`.
        tol_force : float              relative residual tolerance of each Newton solve.
        max_iter : int                 Newton iterations per solve.
        max_rot_rad : float [rad]      largest nodal rotation increment per Newton iteration.
        outer_tol : float              relative change of follower loads / tube stiffness ending the outer iteration.
        max_outer : int                outer iterations per load step (follower pressure, secant tubes).

        Returns
        -------
        FEResult

        Raises
        ------
        ValueError for an ill-posed model; :class:`~kite_env.structure.solver.ConvergenceError` when a Newton solve
        or the outer iteration fails (the message says which load step).
        """
        if not self.sets:
            raise ValueError("FEModel.solve: no elements; add beams, tubes or shells first")
        if int(load_steps) != load_steps or load_steps < 1:
            raise ValueError(f"FEModel.solve: load_steps must be a positive integer, got {load_steps}")
        if not self._constraints:
            raise ValueError("FEModel.solve: no fixed or prescribed DOF; the structure would be free-floating")
        asm = Assembler(self.n_nodes, self.sets)
        unused = asm.unused_nodes
        loads_dead = self._loads + self.pressure_loads(follower=False)
        has_follower = any(fol for _, _, fol in self._pressures)
        if unused.size and (np.any(loads_dead[unused] != 0.0) or (has_follower and np.any(
                self.pressure_loads(follower=True)[unused] != 0.0))):
            raise ValueError(f"FEModel.solve: loads on node(s) {unused[:10]} that belong to no element")
        for bs, props, _ in self._tubes:
            bs.set_stiffness(EI2=props.EI0, EI3=props.EI0, GJ=props.GJ0)
        has_secant = any(sec for _, _, sec in self._tubes)

        fixed = np.array(sorted(self._constraints), dtype=np.int64)
        target = np.array([self._constraints[d] for d in fixed])
        solver = StaticSolver(asm, tol_force=tol_force, max_iter=max_iter, max_rot_rad=max_rot_rad, mode=mode)
        st = NodalState.reference(self.nodes)
        history, total = [], 0
        for k in range(1, int(load_steps) + 1):
            lam = k / load_steps
            du_fixed = target / load_steps
            residuals, its, outer = [], 0, 0
            f_fol = self.pressure_loads(st.x, follower=True) if has_follower else 0.0
            while True:
                outer += 1
                f_ext = (lam * (loads_dead + f_fol)).ravel()
                try:
                    res = solver.solve(st, f_ext, fixed_dofs=fixed, du_fixed=du_fixed)
                except ConvergenceError as exc:
                    raise ConvergenceError(f"FEModel.solve: load step {k}/{load_steps} (factor {lam:.3g}), "
                                           f"outer iteration {outer}: {exc.args[0]}", exc.history) from exc
                du_fixed = None  # prescribed DOF reached: hold them in further outer iterations
                st = res.state
                its += res.iterations
                residuals.extend(h[1] for h in res.history)
                change = 0.0
                if has_follower:
                    f_new = self.pressure_loads(st.x, follower=True)
                    change = float(np.linalg.norm(f_new - f_fol)) / max(float(np.linalg.norm(f_new)), 1e-300)
                    f_fol = f_new
                if has_secant:
                    change = max(change, self._update_tubes(st))
                if change <= outer_tol:
                    break
                if outer >= max_outer:
                    raise ConvergenceError(f"FEModel.solve: outer iteration (follower pressure / secant tube "
                                           f"stiffness) did not converge in load step {k}: change {change:.2e}",
                                           [(outer, change, np.nan)])
            total += its
            history.append({"step": k, "load_factor": lam, "outer": outer, "iterations": its,
                            "residuals": residuals})

        reactions = np.zeros(asm.n_dof)
        reactions[fixed] = res.reactions[fixed]
        info = {}
        if self._tubes:
            flags = []
            for bs, props, _ in self._tubes:
                flags.append(tube.collapsed(props, self._tube_strains(bs, st)[0]))
            info["tube_collapsed"] = np.concatenate(flags)
        return FEResult(positions=st.x, displacements=st.x - self.nodes, rotations=st.Rn,
                        reactions=reactions.reshape(-1, DOF_PER_NODE), iterations=total, history=history, info=info)


__all__ = ["FEModel", "FEResult", "CircularRod", "CircularTube", "DOF_NAMES"]
