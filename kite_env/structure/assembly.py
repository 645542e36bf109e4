"""Vectorised global assembly of element sets with a sparsity pattern built once.

Every element set (:class:`kite_env.structure.beam.BeamSet`, :class:`kite_env.structure.shell.ShellSet`, ...)
exposes ``conn`` (n_e, n_en) and ``internal(x_e, R_e) -> (f_e, K_e)`` with 6 DOF per node ``[du, dw]``.
The :class:`Assembler` precomputes, once, the compressed-sparse-column (CSC) structure of the global tangent
and for every element-matrix entry the position of its value in the CSC data array. An assembly is then one
``np.bincount`` for the internal force and one for the matrix values: no Python loop over elements and no
re-sorting of indices (scikit-fem and most production FE codes do the same).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

DOF_PER_NODE = 6


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
        Element sets, each with ``conn`` and ``internal(x_e, R_e)``.
    """

    def __init__(self, n_nodes: int, sets: list):
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
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
        # diagonal entries always present so that prescribed/unused DOF can be handled uniformly
        diag = np.arange(self.n_dof)
        rows = np.concatenate([rows, diag])
        cols = np.concatenate([cols, diag])
        key = cols * self.n_dof + rows  # column-major order = CSC
        uniq, inv = np.unique(key, return_inverse=True)
        self.nnz = uniq.size
        self._map = inv[: inv.size - self.n_dof]  # position of each element-matrix entry in the CSC data
        self.indices = (uniq % self.n_dof).astype(np.int32)
        self.indptr = np.searchsorted(uniq // self.n_dof, np.arange(self.n_dof + 1)).astype(np.int32)
        self._node_used = np.zeros(self.n_nodes, bool)
        for s in self.sets:
            self._node_used[np.asarray(s.conn).ravel()] = True

    @property
    def unused_nodes(self) -> np.ndarray:
        """Indices of nodes that belong to no element (their DOF have no stiffness)."""
        return np.flatnonzero(~self._node_used)

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
        f_parts, k_parts, d_parts = [], [], []
        for s, d in zip(self.sets, self._dofs):
            conn = s.conn
            f_e, K_e = s.internal(x[conn], Rn[conn])
            f_parts.append(f_e.ravel())
            d_parts.append(d.ravel())
            if tangent:
                k_parts.append(K_e.ravel())
        f_int = np.bincount(np.concatenate(d_parts), weights=np.concatenate(f_parts), minlength=self.n_dof)
        if not tangent:
            return f_int, None
        data = np.bincount(self._map, weights=np.concatenate(k_parts), minlength=self.nnz)
        return f_int, self.matrix(data)
