"""Compiled (numba) kernels of the assembly: the scatter-add of the element forces into the global vector
(:mod:`kite_env.structure.assembly`) and a product with a sub-pattern of an assembled sparse matrix
(:mod:`kite_env.dynamics.wing_dynamics`), both in the order of operations of their NumPy / scipy references.
Backends, compilation and cost: :mod:`kite_env.compiled`.
"""

from __future__ import annotations

from kite_env.compiled import JIT, njit


@njit(**JIT)
def scatter_add(out, index, values):
    """``out[index[i]] += values[i]`` for all i (unbuffered, like ``np.add.at``; ``out`` is not cleared)."""
    for i in range(index.shape[0]):
        out[index[i]] += values[i]


@njit(**JIT)
def csc_gather_matvec(data, entries, indices, indptr, scale, x, out):
    """``out = (scale A) x`` for the CSC matrix ``A`` whose values are ``data[entries]`` (a sub-pattern of a larger
    pattern's data, e.g. its translation-translation entries) with ``indices`` and ``indptr``: scipy's product of
    ``csc_matrix((scale * data[entries], indices, indptr))`` in the same order of operations, without gathering
    the values into a new matrix. ``out`` (length of ``x``) is overwritten."""
    out[:] = 0.0
    for j in range(indptr.shape[0] - 1):
        xj = x[j]
        for k in range(indptr[j], indptr[j + 1]):
            out[indices[k]] += (scale * data[entries[k]]) * xj
