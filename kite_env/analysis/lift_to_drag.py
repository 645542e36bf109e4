"""The wing's lift-to-drag ratio split into its two factors: the sections' own L/D and the C-shaped arc's projection
(analyses/mesh_refinement.py; docs/validation.md, "Mesh refinement, L/D, the figure's elevation")."""

from __future__ import annotations

import numpy as np


def lift_to_drag_factors(section_forces, v_ref) -> tuple[float, float, float]:
    """``(wing L/D, sections' L/D, projection)`` of the nodal aerodynamic forces ``section_forces`` (n_sec, m, 3) [N]
    (a solution's :attr:`kite_env.fsi.WingSolution.section_forces`) about the reference apparent velocity ``v_ref``
    (3,) [m/s]; the first is the product of the other two. Each section's force splits into its drag ``D_i`` along
    the reference flow and its lift ``L_i`` across it: the sections' own L/D is ``sum_i |L_i| / sum_i D_i`` (Breukels'
    2-D regression at each section's angle), the projection ``|sum_i L_i| / sum_i |L_i|`` (the sections' lifts point
    in different directions around the arc, their drags add up)."""
    F = np.asarray(section_forces, dtype=float).sum(axis=1)
    e_d = -np.asarray(v_ref, dtype=float) / np.linalg.norm(v_ref)
    D = F @ e_d
    L = F - np.outer(D, e_d)
    lift_sum = float(np.sum(np.linalg.norm(L, axis=1)))
    return (float(np.linalg.norm(L.sum(axis=0)) / D.sum()), lift_sum / float(D.sum()),
            float(np.linalg.norm(L.sum(axis=0))) / lift_sum)
