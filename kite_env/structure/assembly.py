"""Vectorised global assembly of element sets with a sparsity pattern built once.

Every element set (:class:`kite_env.structure.beam.BeamSet`, :class:`kite_env.structure.shell.ShellSet`, ...)
exposes ``conn`` (n_e, n_en) and ``internal(x_e, R_e, tangent=True) -> (f_e, K_e)`` with 6 DOF per node
``[du, dw]``; with ``tangent=False`` a set may return ``K_e = None`` (residual-only assemblies).
The :class:`Assembler` precomputes, once, the compressed-sparse-column (CSC) structure of the global tangent
and for every element-matrix entry the position of its value in the CSC data array. An assembly is then one
``np.bincount`` for the internal force and one for the matrix values: no Python loop over elements and no
re-sorting of indices (scikit-fem and most production FE codes do the same).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

DOF_PER_NODE = 6


def _numba_scatter():
    """The compiled scatter-add kernel when the numba element backend is in use, else None (``np.bincount``)."""
    from kite_env.compiled import resolve_backend

    if resolve_backend("auto") != "numba":
        return None
    from .assembly_kernels import scatter_add

    return scatter_add


def element_dofs(conn: np.ndarray) -> np.ndarray:
    """Global DOF indices of each element, ``(n_e, n_en) -> (n_e, 6 n_en)``, node-major ``[u, w]`` order."""
    conn = np.asarray(conn, dtype=np.int64)
    return (DOF_PER_NODE * conn[:, :, None] + np.arange(DOF_PER_NODE)).reshape(conn.shape[0], -1)


class Assembler:
    """Assemble internal forces and the tangent stiffness of several element sets.

    Parameters
    ----------
    n_nodes : int
        Number of structural nodes; the global system has ``6 n_nodes`` DOF.
    sets : list
        Element sets, each with ``conn`` and ``internal(x_e, R_e, tangent)``.
    extra_blocks : (n_b, n_bn) int array, optional
        Node groups whose translational DOF couple in matrices added to the tangent from outside the element sets
        (the aerodynamic load Jacobian of each wing section, :mod:`kite_env.fsi`). Their entries are made part of
        the pattern; :meth:`block_data` maps ``(n_b, 3 n_bn, 3 n_bn)`` blocks onto it.
    """

    def __init__(self, n_nodes: int, sets: list, extra_blocks: np.ndarray | None = None):
        self.n_nodes = int(n_nodes)
        self.n_dof = DOF_PER_NODE * self.n_nodes
        self.sets = list(sets)
        rows, cols = [], []
        self._dofs = []
        for s in self.sets:
            conn = np.asarray(s.conn)
            if conn.size and (conn.min() < 0 or conn.max() >= self.n_nodes):
                raise ValueError(f"{type(s).__name__}: connectivity refers to nodes outside 0..{self.n_nodes - 1}")
            d = element_dofs(conn)
            self._dofs.append(d)
            k = d.shape[1]
            rows.append(np.repeat(d, k, axis=1).ravel())  # K_e[e, a, b] -> row d[a]
            cols.append(np.tile(d, (1, k)).ravel())  # col d[b]
        n_extra = 0
        if extra_blocks is not None:
            eb = np.asarray(extra_blocks, dtype=np.int64)
            if eb.size and (eb.min() < 0 or eb.max() >= self.n_nodes):
                raise ValueError(f"extra_blocks refer to nodes outside 0..{self.n_nodes - 1}")
            d = (DOF_PER_NODE * eb[:, :, None] + np.arange(3)).reshape(eb.shape[0], -1)
            k = d.shape[1]
            rows.append(np.repeat(d, k, axis=1).ravel())
            cols.append(np.tile(d, (1, k)).ravel())
            n_extra = rows[-1].size
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        # diagonal entries always present so that prescribed/unused DOF can be handled uniformly
        diag = np.arange(self.n_dof)
        rows = np.concatenate([rows, diag])
        cols = np.concatenate([cols, diag])
        key = cols * self.n_dof + rows  # column-major order = CSC
        uniq, inv = np.unique(key, return_inverse=True)
        self.nnz = uniq.size
        n_el = inv.size - self.n_dof - n_extra
        self._map = inv[:n_el]  # position of each element-matrix entry in the CSC data
        sizes = np.cumsum([0] + [d.shape[0] * d.shape[1] ** 2 for d in self._dofs])
        # per element set, where each of its element-matrix entries lands in the CSC data (read by the wing with
        # inertia to add its shells' blocks of another matrix into the same pattern)
        self.set_maps = [self._map[a:b] for a, b in zip(sizes[:-1], sizes[1:])]
        self._set_dofs = [d.ravel() for d in self._dofs]
        self._scatter = _numba_scatter()
        self._extra_map = inv[n_el: n_el + n_extra]
        self.diag_index = inv[n_el + n_extra:]  # position of the diagonal entry (i, i) in the CSC data
        self.indices = (uniq % self.n_dof).astype(np.int32)
        self.indptr = np.searchsorted(uniq // self.n_dof, np.arange(self.n_dof + 1)).astype(np.int32)
        self.node_used = np.zeros(self.n_nodes, bool)  # nodes of some element (the others' DOF have no stiffness)
        for s in self.sets:
            self.node_used[np.asarray(s.conn).ravel()] = True

    @property
    def unused_nodes(self) -> np.ndarray:
        """Indices of nodes that belong to no element (their DOF have no stiffness)."""
        return np.flatnonzero(~self.node_used)

    def block_data(self, blocks: np.ndarray) -> np.ndarray:
        """Pattern data (length ``nnz``) of the ``extra_blocks`` matrices ``(n_b, 3 n_bn, 3 n_bn)``."""
        return np.bincount(self._extra_map, weights=np.asarray(blocks, dtype=float).ravel(), minlength=self.nnz)

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        """CSC matrix on the fixed pattern with the given values (length ``nnz``)."""
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n_dof, self.n_dof))

    def assemble(self, x: np.ndarray, Rn: np.ndarray, tangent: bool = True):
        """Global internal force and tangent.

        Parameters
        ----------
        x : (n_nodes, 3) float [m]
            Current node positions.
        Rn : (n_nodes, 3, 3) float
            Current nodal rotation matrices.
        tangent : bool
            If False only the force is assembled and ``None`` is returned for the matrix.

        Returns
        -------
        f_int : (6 n_nodes,) float [N, N m]
        K : scipy.sparse.csc_matrix (6 n_nodes, 6 n_nodes) or None
        """
        f_int, data = self.assemble_data(x, Rn, tangent)
        return f_int, (self.matrix(data) if tangent else None)

    def assemble_data(self, x: np.ndarray, Rn: np.ndarray, tangent: bool = True):
        """As :meth:`assemble`, with the tangent as its CSC data vector (length ``nnz``; None without tangent)."""
        f_int = np.zeros(self.n_dof)
        data = np.zeros(self.nnz) if tangent else None
        for s, dofs, kmap in zip(self.sets, self._set_dofs, self.set_maps):
            conn = s.conn
            f_e, K_e = s.internal(x[conn], Rn[conn], tangent=tangent)
            if self._scatter is not None:
                self._scatter(f_int, dofs, f_e.ravel())
                if tangent:
                    self._scatter(data, kmap, K_e.ravel())
            else:
                f_int += np.bincount(dofs, weights=f_e.ravel(), minlength=self.n_dof)
                if tangent:
                    data += np.bincount(kmap, weights=K_e.ravel(), minlength=self.nnz)
        return f_int, data
