"""The wing's mass on its bridle points: nodal masses of the FE wing, condensed onto A-D (Guyan reduction).

The paper (Sect. II.C, Table 1) puts the wing's 10 kg into four point masses at the bridle points A-D, 70 % at the
leading-edge points. Four points carry the right total mass but not its distribution: the wing's pitch inertia
about its span is about a tenth of a distributed wing's and its yaw inertia about twice (the four points sit at the
tips), which sets the frequency of the wing's yaw/twist mode on its bridle and, with it, whether that mode is
damped (docs/flight_model.md). ``dynamics.wing_mass = "distributed"`` (default) spreads the same mass over the FE
nodes and condenses it onto A-D; ``"points"`` keeps the paper's four point masses.

Nodal masses (:func:`nodal_wing_mass`): the leading-edge share of Table 1 (``2 m_A / (2 m_A + 2 m_B)`` = 70 %) on
the LE-tube nodes in proportion to their strip widths, the rest over all nodes of each section in proportion to the
canopy area each node carries (strip width times half the chordwise distance to its neighbours).

Condensation (:func:`condensed_wing_mass`): the quasi-static wing follows its bridle points, so each node moves as
Guyan's static modes say, ``u = Phi q_b`` with ``Phi_f = -T_ff^-1 T_fb`` from the wing's aeroelastic tangent
(structure and aerodynamic stiffness) at the start of the flight, and the kinetic energy of the nodal masses
``1/2 sum_n m_n |u_n'|^2`` gives the (12, 12) mass matrix ``M = Phi^T M_n Phi`` on A-D in frame K (Guyan 1965,
"Reduction of stiffness and mass matrices", AIAA J. 3(2), 380). A rigid motion of A-D moves every node rigidly (the
static modes contain the rigid-body modes), so ``M`` carries the wing's exact mass, centre of mass and inertia tensor
for rigid motions, and the modal masses of the wing's deformation for the relative motion of A-D. It is held constant
in K over the flight (the shape changes little), and the velocity-dependent inertia terms of the moving frame are
not added (their size is ``m omega^2 r``, about 30 N at 1 rad/s, under 1 % of the wing's load).
"""

from __future__ import annotations

import numpy as np

from kite_env.config import DynamicsConfig


def nodal_wing_mass(mesh, cfg: DynamicsConfig) -> np.ndarray:
    """Translational mass of every FE node (n_nodes,) [kg]: Table 1's total ``2 (m_A + m_B)`` with the LE share
    ``m_A / (m_A + m_B)`` on the LE-tube nodes (by strip width) and the rest on the canopy (by tributary area).

    Parameters
    ----------
    mesh : KiteMesh
        ``sections`` (n_sec, m) node indices (LE node first), ``section_width`` (n_sec,) [m], ``nodes`` [m].
    cfg : DynamicsConfig
        ``mass_le_kg``, ``mass_te_kg``.
    """
    total = 2.0 * (cfg.mass_le_kg + cfg.mass_te_kg)
    le_share = cfg.mass_le_kg / (cfg.mass_le_kg + cfg.mass_te_kg)
    sec = mesh.sections
    x = mesh.nodes[sec]
    w = np.asarray(mesh.section_width, dtype=float)
    seg = np.linalg.norm(np.diff(x, axis=1), axis=2)  # (n_sec, m - 1) chordwise node distances
    trib = np.zeros(sec.shape)
    trib[:, :-1] += 0.5 * seg
    trib[:, 1:] += 0.5 * seg
    area = w[:, None] * trib
    m = np.zeros(mesh.n_nodes)
    np.add.at(m, sec[:, 0], le_share * total * w / w.sum())
    np.add.at(m, sec.ravel(), ((1.0 - le_share) * total * area / area.sum()).ravel())
    return m


def condensed_wing_mass(wing, node_mass: np.ndarray) -> np.ndarray:
    """Guyan-condensed mass matrix of the wing on A-D (12, 12) [kg], frame K (A, B, C, D x, y, z).

    ``wing`` must just have solved with the bridle points prescribed (its factorised aeroelastic tangent gives the
    static modes, :meth:`kite_env.structure.solver.StaticSolver.static_modes`).
    """
    solver = wing._mono_solvers["prescribed"]
    dofs = (6 * wing.bridle[:, None] + np.arange(3)[None, :]).ravel()
    free, phi_f = solver.static_modes(dofs)
    phi = np.zeros((wing.n_dof, dofs.size))
    phi[free] = phi_f
    phi[dofs, np.arange(dofs.size)] = 1.0
    trans = phi.reshape(-1, 6, dofs.size)[:, :3]  # (n_nodes, 3, 12) nodal translations per unit bridle move
    M = np.einsum("n,nka,nkb->ab", node_mass, trans, trans)
    return 0.5 * (M + M.T)
