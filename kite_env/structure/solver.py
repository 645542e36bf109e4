"""Newton-Raphson static solver with prescribed DOF (first and second block of the paper's Eq. 1).

The state is the nodal positions ``x`` and nodal rotation matrices ``Rn``; an increment ``du`` (6 per node) adds
translations and applies rotations as spatial spins, ``Rn <- expm(dw) Rn`` (multiplicative update, see
:mod:`kite_env.structure.rotations`). Prescribed DOF are moved to their target in the first iteration and then held;
the free DOF solve ``K_ff du_f = f_ext,f - f_int,f`` (Eq. 1, first block, loads held fixed). The reactions are
``F_b = f_int,b - f_ext,b`` (Eq. 1, second block).

The sparse reduced matrix ``K_ff`` is extracted from the assembler's fixed pattern with an index map built once per
set of prescribed DOF. ``mode="modified"`` keeps the LU factorisation of a previous iteration (or previous call)
as long as the residual contracts fast enough, which is what makes warm time steps cheap; ``mode="full"`` refactors
every iteration (quadratic convergence). Failure raises :class:`ConvergenceError` with the residual history.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack as _lapack

from .assembly import DOF_PER_NODE, Assembler
from .rotations import expm


def _norm(v: np.ndarray) -> float:
    """Euclidean norm of a 1-D array: ``np.linalg.norm``'s ``sqrt(v . v)`` (the same bits) without its overhead
    (several are taken per Newton iteration)."""
    return math.sqrt(float(v @ v))

#: Multiple of (machine eps x largest diagonal stiffness x model size) below which the residual is round-off.
_ROUNDOFF = 16.0
#: ... and relative size (energy norm squared) of the last Newton correction for such a residual to count as converged.
_WORK_TOL = 1e-14


def _compiled_rotate():
    from kite_env.compiled import resolve_backend

    if resolve_backend("auto") != "numba":
        return None
    from .rotation_kernels import rotate_nodes

    return rotate_nodes


#: compiled ``expm(dw) R`` for all nodes (numba backend), else None (NumPy Rodrigues)
_rotate_nodes = _compiled_rotate()


class _BandedLU:
    """LAPACK ``dgbtrf`` LU with partial pivoting of a banded matrix (``kl = ku = bw``) with a ``solve`` method like
    SuperLU's (1-D or 2-D right-hand sides)."""

    def __init__(self, ab: np.ndarray, bw: int):
        self.bw = bw
        self.lu, self.piv, info = _lapack.dgbtrf(ab, bw, bw, overwrite_ab=True)
        if info != 0:
            raise RuntimeError(f"banded LU: singular matrix (dgbtrf info = {info})")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        x, info = _lapack.dgbtrs(self.lu, self.bw, self.bw, rhs, self.piv)
        if info != 0:
            raise RuntimeError(f"banded LU solve failed (dgbtrs info = {info})")
        return x


class ConvergenceError(RuntimeError):
    """Newton iterations failed; ``history`` holds ``(iteration, residual norm, increment norm)`` tuples."""

    def __init__(self, message: str, history: list):
        tail = "\n".join(f"  it {h[0]:3d}  |r| = {h[1]:.3e}  |du| = {h[2]:.3e}" for h in history[-10:])
        super().__init__(f"{message}\nresidual history (last {min(len(history), 10)}):\n{tail}")
        self.history = list(history)


@dataclass
class NodalState:
    """Nodal positions ``x`` (n_nodes, 3) [m] and rotation matrices ``Rn`` (n_nodes, 3, 3)."""

    x: np.ndarray
    Rn: np.ndarray

    def copy(self) -> NodalState:
        return NodalState(self.x.copy(), self.Rn.copy())

    @classmethod
    def reference(cls, X0: np.ndarray) -> NodalState:
        X0 = np.asarray(X0, dtype=float)
        return cls(X0.copy(), np.broadcast_to(np.eye(3), (X0.shape[0], 3, 3)).copy())

    def updated(self, du: np.ndarray) -> NodalState:
        """New state after the increment ``du`` (6 n_nodes,): translations added, spins applied as rotations."""
        d = du.reshape(-1, DOF_PER_NODE)
        if _rotate_nodes is not None:
            Rn = np.empty_like(self.Rn)
            _rotate_nodes(np.ascontiguousarray(self.Rn), np.ascontiguousarray(d[:, 3:]), Rn)
            return NodalState(self.x + d[:, :3], Rn)
        return NodalState(self.x + d[:, :3], np.einsum("nij,njk->nik", expm(d[:, 3:]), self.Rn))


@dataclass
class StaticResult:
    state: NodalState
    reactions: np.ndarray  # (n_dof,) f_int - f_ext; nonzero at prescribed DOF [N, N m]
    iterations: int
    history: list = field(default_factory=list)
    converged: bool = True
    factorizations: int = 0
    accepted: bool = False  # not converged to the tolerance, but within ``accept_force`` (see StaticSolver.solve)


class StaticSolver:
    """Newton-Raphson on ``f_int(x, Rn) = f_ext`` with prescribed DOF.

    Parameters
    ----------
    assembler : Assembler
    tol_force : float
        Converged when ``|r_f| <= tol_force * max(|f_ext|, |reactions|, force_floor)``, or when ``|r_f|`` sits at
        the round-off floor ``16 eps max|K_ii| max(|x|, 1 m)`` of the internal forces (stiff members under small
        loads) and no longer falls.
    tol_disp : float [m]
        ... and the last translational increment is below ``tol_disp``.
    force_floor : float [N]
        Absolute floor of the residual scale (unloaded problems).
    max_iter : int
    max_rot_rad : float [rad]
        Largest nodal rotation increment per iteration; larger steps are scaled down (keeps Newton inside the
        range where spins are accurate).
    nodal_rot_limit : bool
        Scale down only the rotation increments of the nodes beyond ``max_rot_rad`` instead of the whole
        increment (the wing with inertia: canopy nodes whose rotations the thin shell hardly restrains ask for
        spins of more than 0.5 rad while the translations move by a millimetre, and scaling everything by the
        worst node turned Newton into 20-30 small steps).
    max_step_m : float or None [m]
        Largest translation increment per iteration (None: unlimited).
    mode : "full" | "modified"
        Refactor every iteration, or keep a factorisation while the residual falls by ``contraction`` per step.
    banded : bool
        Factorise with LAPACK's banded LU when the reduced tangent's bandwidth is below 1/8 of its size (DOF
        numbered along a mesh strip), else with SuperLU.
    error_estimate : bool
        The displacement test may also use the estimated error of the iterate instead of the last increment: with
        the rate ``theta = |r_k| / |r_k-1|`` of the last correction ``du``, ``theta / (1 - theta) |du| <= tol_disp``
        (``theta < 1``), the stopping rule of the simplified Newton iteration of implicit Runge-Kutta methods
        (Hairer & Wanner, *Solving Ordinary Differential Equations II*, Sect. IV.8, Eq. 8.10-8.11). The last
        increment alone certifies the iterate before it: one more correction than the tolerance needs.
    """

    def __init__(self, assembler: Assembler, tol_force: float = 1e-8, tol_disp: float = 1e-8,
                 force_floor: float = 1e-6, max_iter: int = 40, max_rot_rad: float = 0.5,
                 max_step_m: float | None = None, mode: str = "full", contraction: float = 0.25,
                 banded: bool = True, nodal_rot_limit: bool = False, error_estimate: bool = False):
        if mode not in ("full", "modified"):
            raise ValueError(f"mode must be 'full' or 'modified', got {mode!r}")
        self.asm = assembler
        self.tol_force = tol_force
        self.tol_disp = tol_disp
        self.force_floor = force_floor
        self.max_iter = max_iter
        self.max_rot_rad = max_rot_rad
        self.nodal_rot_limit = bool(nodal_rot_limit)
        self.error_estimate = bool(error_estimate)
        self.max_step_m = max_step_m
        self.mode = mode
        self.contraction = contraction
        self._sel_cache: dict = {}
        self._lu = None
        self._lu_key = None
        self._lu_snapshot = None  # what the load's tangent_change compares with, taken at the factorisation
        self._lu_block = None  # dense block of the factorised tangent on the DOF of the load's tangent change
        self._block_cache: dict = {}  # per (prescribed DOF, changed DOF): positions of the block (_block_correction)
        self.n_block_corrections = 0
        self._diag_max = 0.0  # largest |K_ii| of the last assembled tangent (round-off floor of the residual)
        self._band_cache: dict = {}  # per set of prescribed DOF: banded-storage map or (None, None, None)
        self._condense_cache: dict = {}  # per (prescribed, free) DOF: data positions of the condensation blocks
        self.banded = banded
        self._lu_data = None  # tangent (pattern data, incl. load tangent) of the current factorisation
        self._lu_free = None
        self.n_factorizations = 0  # counter over the solver's lifetime
        self.auto_fixed = np.flatnonzero(np.repeat(~assembler.node_used, DOF_PER_NODE))

    def _reduced(self, fixed: np.ndarray):
        key = fixed.tobytes()
        hit = self._sel_cache.get(key)
        if hit is None:
            n = self.asm.n_dof
            free = np.setdiff1d(np.arange(n), fixed)
            idx = self.asm.matrix(np.arange(1, self.asm.nnz + 1, dtype=float))
            sub = idx[free][:, free].tocsc()
            sub.sort_indices()
            hit = (free, sub.data.astype(np.int64) - 1, sub.indices.copy(), sub.indptr.copy(), key)
            self._sel_cache[key] = hit
        return hit

    def solve_damped(self, state: NodalState, fixed_dofs, du_fixed, load, tol_force: float, tol_disp: float,
                     max_iter: int = 60, lam0: float = 0.1, accept_force: float | None = None) -> StaticResult:
        """Levenberg-Marquardt-damped Newton for hard cases (a slack, luffing canopy): ``(T + lam D) du = r`` with
        ``D`` the diagonal of the tangent; a step that does not lower the residual norm is rejected and ``lam``
        grows (x4), an accepted one shrinks it (x0.3). Refactorises every iteration. Same convergence test and
        result as :meth:`solve` (with a configuration-dependent ``load``); the damping changes only the path.
        """
        n = self.asm.n_dof
        fixed_in = np.asarray(fixed_dofs, dtype=np.int64).ravel()
        fixed = np.union1d(fixed_in, self.auto_fixed)
        free, sel, ind, ptr, key = self._reduced(fixed)
        du0 = np.zeros(n)
        du0[fixed_in] = np.asarray(du_fixed, dtype=float).ravel()
        st = state.updated(du0) if np.any(du0) else state.copy()

        def residual(s):
            f_ext = np.asarray(load.force(s), dtype=float)
            f_int, kdata = self.asm.assemble_data(s.x, s.Rn, tangent=True)
            r = f_ext - f_int
            scale = max(np.linalg.norm(f_ext[free]), self.force_floor, float(np.linalg.norm(r[fixed])))
            return r, kdata, scale

        r, kdata, scale = residual(st)
        lam = lam0
        history = []
        nfac = 0
        best = (np.inf, None, None)
        for it in range(1, max_iter + 1):
            rnorm = float(np.linalg.norm(r[free]))
            if not np.isfinite(rnorm):
                raise ConvergenceError("non-finite residual in the damped Newton solve", history)
            if rnorm / scale < best[0]:
                best = (rnorm / scale, st, r)
            last_du = history[-1][2] if history else np.inf
            if rnorm <= tol_force * scale and last_du <= tol_disp:
                history.append((it, rnorm, 0.0))
                self._store_factorization(kdata + load.tangent(st), sel, ind, ptr, free, key, load)
                return StaticResult(st, -r, it - 1, history, True, nfac + 1)
            data = kdata + load.tangent(st)
            diag = np.abs(data[self.asm.diag_index])
            accepted_step = False
            for _ in range(8):
                d = data.copy()
                d[self.asm.diag_index] += lam * np.maximum(diag, 1e-12 * diag.max())
                try:
                    lu = self._factorize(d, sel, ind, ptr, free, key)
                except RuntimeError:
                    lam *= 4.0
                    continue
                nfac += 1
                du = np.zeros(n)
                du[free] = lu.solve(r[free])
                trial = st.updated(du)
                r_t, k_t, s_t = residual(trial)
                if np.all(np.isfinite(r_t)) and np.linalg.norm(r_t[free]) < rnorm:
                    st, r, kdata, scale = trial, r_t, k_t, s_t
                    lam *= 0.3
                    accepted_step = True
                    break
                lam *= 4.0
            history.append((it, rnorm, float(np.max(np.abs(du.reshape(-1, DOF_PER_NODE)[:, :3])))
                            if accepted_step else np.nan))
            if not accepted_step:
                break
        if accept_force is not None and best[0] <= accept_force:
            _, k_b, _ = residual(best[1])
            self._store_factorization(k_b + load.tangent(best[1]), sel, ind, ptr, free, key, load)
            return StaticResult(best[1], -best[2], max_iter, history, False, nfac + 1, accepted=True)
        raise ConvergenceError(f"damped Newton did not converge in {len(history)} iterations", history)

    def _store_factorization(self, data, sel, ind, ptr, free, key, load) -> None:
        """Factorise the (undamped) tangent at a solution and keep it for later modified-Newton solves."""
        try:
            self._lu = self._factorize(data, sel, ind, ptr, free, key)
        except RuntimeError:
            self._lu = None
            return
        self._lu_key = (key, getattr(load, "tangent_key", None))
        self._lu_data = data
        self._lu_free = free
        self.n_factorizations += 1

    def condensed_tangent(self, dofs: np.ndarray) -> np.ndarray:
        """Stiffness ``d r_b / d q_b`` (len(dofs) square) of the reactions at the prescribed ``dofs`` with the free DOF
        in equilibrium: ``T_bb - T_bf T_ff^-1 T_fb`` with the tangent ``T`` of the current factorisation (which the
        modified Newton may have kept from an earlier iterate: an approximation of the tangent at the solution).
        ``dofs`` must be the prescribed DOF of the last solve."""
        if self._lu is None:
            raise RuntimeError("condensed_tangent needs a factorisation (call solve first)")
        dofs = np.asarray(dofs, dtype=np.int64)
        free = self._lu_free
        key = (dofs.tobytes(), free.tobytes())
        blocks = self._condense_cache.get(key)
        if blocks is None:
            # positions in the tangent's data array of the three blocks (-1: structural zero), built once
            idx = self.asm.matrix(np.arange(1, self.asm.nnz + 1, dtype=float)).tocsr()
            blocks = tuple(idx[rows][:, cols].toarray().astype(np.int64) - 1
                           for rows, cols in ((dofs, dofs), (free, dofs), (dofs, free)))
            self._condense_cache[key] = blocks
        data = np.append(self._lu_data, 0.0)  # index -1 reads the appended zero
        T_bb, T_fb, T_bf = (data[b] for b in blocks)
        return T_bb - T_bf @ self._lu.solve(T_fb)

    def static_modes(self, dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Guyan's static modes of the prescribed ``dofs``: the response ``Phi_f = -T_ff^-1 T_fb`` (n_free, len(dofs))
        of the free DOF to unit moves of the prescribed ones, with the free DOF in equilibrium (Guyan 1965, AIAA J.
        3(2), 380), from the tangent of the current factorisation. Returns ``(free, Phi_f)``; ``dofs`` must be the
        prescribed DOF of the last solve."""
        if self._lu is None:
            raise RuntimeError("static_modes needs a factorisation (call solve first)")
        self.condensed_tangent(dofs)  # builds the block index cache
        free = self._lu_free
        _, T_fb_idx, _ = self._condense_cache[(np.asarray(dofs, dtype=np.int64).tobytes(), free.tobytes())]
        data = np.append(self._lu_data, 0.0)
        return free.copy(), -self._lu.solve(data[T_fb_idx])

    def _factorize(self, data, sel, ind, ptr, free, key):
        """LU of the reduced tangent: LAPACK banded (``gbtrf``) when the DOF numbering gives a narrow band (the kite
        mesh numbered section by section: bandwidth 47 of 1320 DOF, ~4x faster than SuperLU), else SuperLU.
        Raises RuntimeError for a singular matrix (both backends)."""
        band = self._band_cache.get(key)
        if band is None:
            cols = np.repeat(np.arange(free.size), np.diff(ptr))
            bw = int(np.max(np.abs(ind - cols))) if ind.size else 0
            if self.banded and free.size >= 64 and 8 * bw < free.size:
                rows_ab = 2 * bw + bw  # LAPACK storage: 2 kl + ku + 1 rows with kl = ku = bw
                # position in the Fortran-ordered (column-major) band array that dgbtrf factorises in place
                band = (bw, (bw + bw + ind - cols) + cols * (rows_ab + 1), rows_ab + 1)
            else:
                band = (None, None, None)
            self._band_cache[key] = band
        bw, flat, n_rows = band
        if bw is None:
            Kff = sp.csc_matrix((data[sel], ind, ptr), shape=(free.size, free.size))
            return spla.splu(Kff, permc_spec="COLAMD", options={"SymmetricMode": False})
        ab = np.zeros(n_rows * free.size)
        ab[flat] = data[sel]
        return _BandedLU(ab.reshape(free.size, n_rows).T, bw)  # (a view in Fortran order: no copy)

    def _block_correction(self, duf: np.ndarray, change: tuple, free: np.ndarray, key) -> None:
        """Correct the Newton increment ``duf`` (free DOF, in place) of a kept factorisation for a change of the
        tangent confined to a few DOF: ``change = (dofs, dT)``, the DOF (full numbering) and the dense change
        ``dT`` of the tangent on them since the factorisation. With ``du1 = T_LU^-1 r`` the increment of the
        updated tangent is ``du1 + e``, ``(T_LU + dT) e = -dT du1``; ``e`` is taken on the block alone,
        ``(T_LU + dT)_bb e_b = -dT du1_b`` (one block-Jacobi sweep: the rest of the wing held), which costs a
        dense solve of the block's size instead of a factorisation. The factorised tangent's block is read from
        its data once per factorisation."""
        dofs, dT = change
        ck = (key, dofs.tobytes())
        cache = self._block_cache.get(ck)
        if cache is None:
            pos = np.full(self.asm.n_dof, -1, dtype=np.int64)
            pos[free] = np.arange(free.size)
            keep = pos[dofs] >= 0  # (prescribed DOF are left out)
            idx = self.asm.matrix(np.arange(1, self.asm.nnz + 1, dtype=float)).tocsr()[dofs[keep]][:, dofs[keep]]
            cache = self._block_cache[ck] = (pos[dofs[keep]], keep, idx.toarray().astype(np.int64) - 1)
        p, keep, idx = cache
        if self._lu_block is None:
            self._lu_block = np.append(self._lu_data, 0.0)[idx]  # (index -1: a structural zero)
        if not keep.all():
            dT = dT[np.ix_(keep, keep)]
        du_b = duf[p]
        try:
            duf[p] = du_b + np.linalg.solve(self._lu_block + dT, -dT @ du_b)
        except np.linalg.LinAlgError:
            return  # (a singular block: the increment of the kept factorisation as it is)
        self.n_block_corrections += 1

    def forget_factorization(self) -> None:
        self._lu = None
        self._lu_key = None
        self._lu_snapshot = None

    def solve(self, state: NodalState, f_ext: np.ndarray | None, fixed_dofs=(), du_fixed=None,
              max_iter: int | None = None, allow_partial: bool = False, load=None, tol_force: float | None = None,
              tol_disp: float | None = None, accept_force: float | None = None) -> StaticResult:
        """Equilibrium from the start ``state`` with loads ``f_ext`` held fixed.

        Parameters
        ----------
        state : NodalState
            Start (the previous solution for a warm start). Not modified.
        f_ext : (n_dof,) float [N, N m]
            External nodal loads (loads at prescribed DOF only enter the reactions).
        fixed_dofs : int array
            Prescribed DOF indices (unused nodes are fixed automatically).
        du_fixed : float array like ``fixed_dofs`` or None
            Increment of the prescribed DOF relative to ``state`` (None: held where they are).
        max_iter : int or None
            Iteration limit of this call (None: the solver's ``max_iter``).
        allow_partial : bool
            Return the last (finite) iterate with ``converged=False`` instead of raising when the limit is reached;
            used by the aeroelastic coupling, which updates the loads between a few Newton steps.
        load : object, optional
            Configuration-dependent loads (then ``f_ext`` is ignored and may be None): ``load.force(state)`` returns
            the load vector (n_dof,) at an iterate and is called once per iteration before the assembly (it may also
            update state-dependent element properties); ``load.tangent(state)`` returns the pattern data (length
            ``nnz``, see :meth:`Assembler.block_data`) of ``-d f_ext / d x``, added to the tangent whenever it is
            factorised. The residual ``f_ext(x) - f_int(x)`` is then solved monolithically. A load that had to
            assemble the structure at an iterate itself may hand the result over: ``load.assembled(state)`` returns
            ``(f_int, tangent data)`` of that iterate, or None. A load whose tangent changes fast on a few DOF may
            keep a factorisation useful for longer: ``load.tangent_snapshot(state)`` is taken where the tangent is
            factorised, and ``load.tangent_change(state, snapshot)`` returns ``(dofs, dT)`` (the change of the
            tangent on those DOF since then, dense) or None; the increments of a kept factorisation are corrected
            for it (:meth:`_block_correction`).
        tol_force, tol_disp : float, optional
            Override the solver's tolerances for this call.
        accept_force : float, optional
            When the iteration limit is reached, return the iterate with the smallest residual (``converged=False``,
            ``accepted=True``) if that residual is below ``accept_force`` times the load scale, instead of raising.
            For stalls at a residual far below the physics' resolution (Newton chattering between the taut and
            slack states of a wrinkling membrane, or across the kink of a max() in the loads).

        Returns
        -------
        StaticResult
        """
        n = self.asm.n_dof
        tol_force = self.tol_force if tol_force is None else float(tol_force)
        tol_disp = self.tol_disp if tol_disp is None else float(tol_disp)
        if load is None:
            f_ext = np.asarray(f_ext, dtype=float)
            if f_ext.shape != (n,):
                raise ValueError(f"f_ext must have shape ({n},), got {f_ext.shape}")
            if not np.all(np.isfinite(f_ext)):
                raise ValueError("f_ext contains non-finite values")
        fixed_in = np.asarray(fixed_dofs, dtype=np.int64).ravel()
        fixed = np.union1d(fixed_in, self.auto_fixed)
        free, sel, ind, ptr, key = self._reduced(fixed)
        du0 = np.zeros(n)
        if du_fixed is not None:
            du_fixed = np.asarray(du_fixed, dtype=float).ravel()
            if du_fixed.shape != fixed_in.shape:
                raise ValueError("du_fixed must have the same length as fixed_dofs")
            du0[fixed_in] = du_fixed
        st = state.updated(du0) if np.any(du0) else state.copy()
        history = []
        nfac = 0
        r_prev = np.inf
        work_first, work_last = 0.0, np.inf  # |r . du| of the first and of the last Newton correction
        if load is None:
            f_scale = max(_norm(f_ext[free]), self.force_floor)
        max_iter = self.max_iter if max_iter is None else int(max_iter)
        # a factorisation is reused only for the same prescribed DOF and the same kind of load tangent
        lu_key = (key, getattr(load, "tangent_key", None))
        best = (np.inf, None, None, None)  # (relative residual, state, residual vector, iteration)
        force_K = False  # refactor at this iterate (a step with a reused factorisation was rejected)
        stale_step = False  # the last step was made with a factorisation from an earlier iterate
        prev_st = st
        for it in range(1, max_iter + 1):
            if load is not None:
                f_ext = np.asarray(load.force(st), dtype=float)
                f_scale = max(_norm(f_ext[free]), self.force_floor)
            # the tangent is assembled only when it will be factorised (modified Newton reuses the last LU)
            want_K = self.mode == "full" or self._lu is None or self._lu_key != lu_key or force_K
            pre = load.assembled(st) if load is not None and hasattr(load, "assembled") else None
            f_int, kdata = pre if pre is not None else self.asm.assemble_data(st.x, st.Rn, tangent=want_K)
            if kdata is not None:
                self._diag_max = float(np.max(np.abs(kdata[self.asm.diag_index])))
            r = f_ext - f_int
            rf = r[free]
            rnorm = _norm(rf)
            if not np.isfinite(rnorm):
                history.append((it, rnorm, np.nan))
                raise ConvergenceError("non-finite residual in the static solve", history)
            scale = max(f_scale, _norm(r[fixed]))
            if rnorm / scale < best[0]:
                best = (rnorm / scale, st, r, it)
            # Round-off floor of f_int: an element force such as EA/L0 (l - L0) carries an absolute error of about
            # eps |x| EA/L0, so with stiff members and small loads |r| can stagnate above tol_force * scale however
            # many iterations are made. After at least one Newton correction, a residual below that floor counts as
            # converged once the last correction is negligible in the energy norm (|r . du| relative to the first
            # iteration's) or the residual has stopped falling (less than halved: Newton is stirring round-off).
            if it == 1:  # from the start state only, so that a diverging iterate cannot inflate it
                floor = _ROUNDOFF * np.finfo(float).eps * self._diag_max \
                    * max(float(np.max(np.abs(st.x))), 1.0)
            at_floor = it >= 2 and rnorm <= floor and (work_last <= _WORK_TOL * work_first or rnorm > 0.5 * r_prev)
            last_du = history[-1][2] if history else np.inf
            if self.error_estimate and it >= 2 and rnorm < r_prev:  # (a contraction of the last correction)
                theta = rnorm / r_prev
                last_du = min(last_du, theta / (1.0 - theta) * last_du)
            if at_floor or (rnorm <= tol_force * scale
                            and (last_du <= tol_disp or rnorm <= 1e-3 * tol_force * scale)):
                history.append((it, rnorm, 0.0))
                return StaticResult(st, -r, it - 1, history, True, nfac)
            if stale_step and rnorm > r_prev:
                # the step with the old factorisation made things worse: go back and refactor there
                history.append((it, rnorm, np.nan))
                st, force_K, stale_step = prev_st, True, False
                continue
            refactor = want_K or rnorm > self.contraction * r_prev
            force_K = False
            if refactor:
                if kdata is None:
                    _, kdata = self.asm.assemble_data(st.x, st.Rn, tangent=True)
                    self._diag_max = float(np.max(np.abs(kdata[self.asm.diag_index])))
                data = kdata if load is None else kdata + load.tangent(st)
                try:
                    self._lu = self._factorize(data, sel, ind, ptr, free, key)
                except RuntimeError as exc:  # singular matrix
                    history.append((it, rnorm, np.nan))
                    raise ConvergenceError(f"tangent factorisation failed: {exc}", history) from exc
                self._lu_key = lu_key
                self._lu_data = data
                self._lu_block = None
                self._lu_snapshot = load.tangent_snapshot(st) if hasattr(load, "tangent_snapshot") else None
                self._lu_free = free
                self.n_factorizations += 1
                nfac += 1
            stale_step = not refactor
            duf = self._lu.solve(rf)
            if not refactor and self._lu_snapshot is not None and hasattr(load, "tangent_change"):
                change = load.tangent_change(st, self._lu_snapshot)
                if change is not None:
                    self._block_correction(duf, change, free, key)
            if not np.all(np.isfinite(duf)):
                history.append((it, rnorm, np.nan))
                raise ConvergenceError("non-finite Newton increment (singular tangent?)", history)
            work_last = abs(float(rf @ duf))
            if it == 1:
                work_first = work_last
            du = np.zeros(n)
            du[free] = duf
            d6 = du.reshape(-1, DOF_PER_NODE)
            fac = 1.0
            rot_n = np.linalg.norm(d6[:, 3:], axis=1) if d6.size else np.zeros(0)
            rot = float(np.max(rot_n)) if d6.size else 0.0
            if rot > self.max_rot_rad:
                if self.nodal_rot_limit:
                    big = rot_n > self.max_rot_rad
                    d6[big, 3:] *= (self.max_rot_rad / rot_n[big])[:, None]
                else:
                    fac = self.max_rot_rad / rot
            if self.max_step_m is not None:
                tr = float(np.max(np.linalg.norm(d6[:, :3], axis=1)))
                if tr * fac > self.max_step_m:
                    fac = self.max_step_m / tr
            du *= fac
            dnorm = float(np.max(np.abs(d6[:, :3]))) if d6.size else 0.0
            history.append((it, rnorm, dnorm))
            r_prev = rnorm
            prev_st = st
            st = st.updated(du)
        if load is not None:
            f_ext = np.asarray(load.force(st), dtype=float)
        f_int, _ = self.asm.assemble(st.x, st.Rn, tangent=False)
        r = f_ext - f_int
        history.append((max_iter + 1, float(np.linalg.norm(r[free])), np.nan))
        if allow_partial and np.all(np.isfinite(r)):
            return StaticResult(st, -r, max_iter, history, False, nfac)
        if accept_force is not None and best[0] <= accept_force:
            return StaticResult(best[1], -best[2], max_iter, history, False, nfac, accepted=True)
        raise ConvergenceError(f"Newton did not converge in {max_iter} iterations", history)

