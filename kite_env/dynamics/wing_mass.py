"""The wing's mass on its bridle points: nodal masses of the FE wing, condensed onto A-D (Guyan reduction).

The paper (Sect. II.C, Table 1) puts the wing's 10 kg into four point masses at the bridle points A-D, 70 % at the
leading-edge points. Four points carry the right total mass but not its distribution: the wing's pitch inertia
about its span is about a tenth of a distributed wing's and its yaw inertia about twice (the four points sit at the
tips), which sets the frequency of the wing's yaw/twist mode on its bridle and, with it, whether that mode is
damped (docs/model.md, "The yaw/twist mode"). ``dynamics.wing_point_mass_share`` (default 0.6; 1 = the paper) keeps
that share of
the mass as the paper's point masses and spreads the rest over the FE nodes, condensed onto A-D. A point share is
needed while A-D are explicit particles: the condensed modes put only about 0.04 kg at the trailing-edge points
B and D along their lines, and the bridle-line dampers (c_c = 251.7 N s/m, Table 1) on such a mass have a decay rate
of 6,300 1/s, far beyond the RK4 step's stability limit (|lambda dt| < 2.78); 0.6 of Table 1's 1.5 kg keeps it
stable up to dt = 10 ms. (A-D integrated implicitly with a wing that has mass remove the constraint.)

Nodal masses (:func:`nodal_wing_mass`): the leading-edge share of Table 1 (``2 m_A / (2 m_A + 2 m_B)`` = 70 %) on
the LE-tube nodes in proportion to their strip widths, the rest over all nodes of each section in proportion to the
canopy area each node carries (strip width times half the chordwise distance to its neighbours).

Condensation (:func:`condensed_wing_mass`): the quasi-static wing follows its bridle points, so each node moves as
Guyan's static modes say, ``u = Phi q_b`` with ``Phi_f = -K_ff^-1 K_fb`` from the elastic stiffness of the wing
taken stress-free in its loaded start shape, and the kinetic energy of the nodal masses
``1/2 sum_n m_n |u_n'|^2`` gives the (12, 12) mass matrix ``M = Phi^T M_n Phi`` on A-D in frame K (Guyan 1965,
"Reduction of stiffness and mass matrices", AIAA J. 3(2), 380). A rigid motion of A-D moves every node rigidly (the
static modes contain the rigid-body modes), so ``M`` carries the wing's exact mass, centre of mass and inertia tensor
for rigid motions, and the modal masses of the wing's deformation for the relative motion of A-D. It is held constant
in K over the flight (the shape changes little after the start), and the velocity-dependent inertia terms of the moving
frame are not added (their size is ``m omega^2 r``, about 30 N at 1 rad/s, under 1 % of the wing's load).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kite_env.config import DynamicsConfig


def chordwise_tributary(mesh) -> np.ndarray:
    """Chordwise tributary length of every section node (n_sec, m) [m]: half of each adjacent node distance."""
    seg = np.linalg.norm(np.diff(mesh.nodes[mesh.sections], axis=1), axis=2)  # (n_sec, m - 1)
    trib = np.zeros(mesh.sections.shape)
    trib[:, :-1] += 0.5 * seg
    trib[:, 1:] += 0.5 * seg
    return trib


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
    w = np.asarray(mesh.section_width, dtype=float)
    area = w[:, None] * chordwise_tributary(mesh)
    m = np.zeros(mesh.n_nodes)
    np.add.at(m, sec[:, 0], le_share * total * w / w.sum())
    np.add.at(m, sec.ravel(), ((1.0 - le_share) * total * area / area.sum()).ravel())
    return m


def nodal_rotary_inertia(mesh, node_mass: np.ndarray) -> np.ndarray:
    """Isotropic rotary inertia of every FE node (n_nodes,) [kg m^2]: ``J = m (a^2 + b^2) / 24`` of its mass ``m``
    spread over its tributary rectangle, ``a`` its chordwise tributary length and ``b`` its section's width (the
    mean of the rectangle's two in-plane second moments ``m a^2 / 12`` and ``m b^2 / 12``; lumped rotary inertia as
    in Hinton, Rock & Zienkiewicz, Earthquake Eng. Struct. Dyn. 4, 245, 1976). A node outside the sections gets 0.
    """
    sec = mesh.sections
    trib = chordwise_tributary(mesh)
    b = np.broadcast_to(np.asarray(mesh.section_width, dtype=float)[:, None], sec.shape)
    J = np.zeros(mesh.n_nodes)
    np.add.at(J, sec.ravel(), (np.asarray(node_mass)[sec] * (trib**2 + b**2) / 24.0).ravel())
    return J


def condensed_wing_mass(wing, node_mass: np.ndarray, shape: np.ndarray | None = None) -> np.ndarray:
    """Guyan-condensed mass matrix of the wing on A-D (12, 12) [kg], frame K (A, B, C, D x, y, z).

    The static modes are those of the elastic wing taken stress-free in ``shape`` (n_nodes, 3) [m] (default: the
    design shape; the flight passes its loaded start shape): a rigid motion of that shape strains nothing, so the
    modes contain the rigid-body modes exactly and ``M`` carries the wing's mass, centre of mass and inertia tensor
    in that shape. The loaded aeroelastic tangent would not: its prestress (geometric stiffness) and the aerodynamic
    loads, which do not turn with a rotated wing, make a rigid rotation of A-D deform the wing instead (measured:
    pitch inertia 0.14, yaw inertia 1.8 times the true values); and the design shape's modes applied to the loaded
    bridle points (tips about 1 m closer) give a roll inertia 26 % low.
    """
    from kite_env.fsi import AeroelasticWing

    mesh = wing.mesh
    if shape is not None:
        x = np.asarray(shape, dtype=float)
        e = x[mesh.beams[:, 1]] - x[mesh.beams[:, 0]]
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        up = mesh.beam_up - np.einsum("ij,ij->i", mesh.beam_up, e)[:, None] * e  # keep the beams' up vectors normal
        mesh = dataclasses.replace(mesh, nodes=x, beam_up=up / np.linalg.norm(up, axis=1, keepdims=True))
    ref = AeroelasticWing(mesh, wing.cfg)  # the structure, stress-free in ``shape``
    dofs = (6 * ref.bridle[:, None] + np.arange(3)[None, :]).ravel()
    ref.solver.solve(ref.unloaded_state(), np.zeros(ref.n_dof), dofs, np.zeros(dofs.size))
    free, phi_f = ref.solver.static_modes(dofs)
    phi = np.zeros((ref.n_dof, dofs.size))
    phi[free] = phi_f
    phi[dofs, np.arange(dofs.size)] = 1.0
    trans = phi.reshape(-1, 6, dofs.size)[:, :3]  # (n_nodes, 3, 12) nodal translations per unit bridle move
    M = np.einsum("n,nka,nkb->ab", node_mass, trans, trans)
    return 0.5 * (M + M.T)
