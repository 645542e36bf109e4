"""Compiled (numba) kernel of the inflated tubes' stiffness law (:mod:`kite_env.structure.tube`).

:func:`tube_secants` computes Breukels' secant bending and torsional stiffnesses of the tube beams, the fold
contact of a kinked tube and the material tangent terms from the beams' local end rotations
(:func:`kite_env.structure.beam_kernels.beam_local_rotations`), as
``AeroelasticWing.update_tube_stiffness`` (:mod:`kite_env.fsi`) does with the NumPy functions of
:mod:`kite_env.structure.tube`.  Backends, compilation and cost: :mod:`kite_env.compiled`.
"""

from __future__ import annotations

import math

from kite_env.compiled import JIT, njit

#: below this normalised curvature / twist the material tangent terms of the secant law are 0 (m = 0 there)
_SECANT_TINY = 1e-12
#: the fold contact's linear continuation (tube._FOLD_LINEAR; a literal, not an import: numba's cache is keyed on
#: this file only, so a changed import would not recompile; tests/structure/test_kernels.py checks that it is equal)
_FOLD_LINEAR = 0.9


@njit(**JIT)
def tube_secants(th, L0, rows, EI0, M_max, kappa_collapse, GJ0, c2, kappa_fold, kappa_closed, energy, with_tangent,
                 EI_out, GJ_out, collapsed_out, gb_out, gt_out):
    """Breukels' secant tube stiffnesses from the local end rotations (``AeroelasticWing.update_tube_stiffness``).

    th : (n_beams, 2, 3) float [rad], L0 : (n_beams,) float [m]   local end rotations (:func:`beam_local_rotations`)
    and the lengths the curvatures are per (unloaded for ``energy``, the current chord for the larger-end law);
    rows : (n_tube,) int   the tube beams; EI0, M_max, kappa_collapse, GJ0, c2, kappa_fold,
    kappa_closed : (n_tube,) float   :class:`kite_env.structure.tube.TubeProperties` (the fold contact of
    :func:`kite_env.structure.tube.fold_contact` where ``kappa_fold`` is finite); energy : bool   the curvature
    measure, True: the element's root-mean-square curvature ``sqrt(4 (th1^2 + th1 th2 + th2^2)) / L0`` over both
    bending components (the secant law is then the gradient of an energy), False: the larger end curvature of the
    cubic element, ``|-(4 th1 + 2 th2)| / L0`` and ``|(2 th1 + 4 th2)| / L0``. Outputs (n_tube,): secant
    ``EI = M(kappa) / kappa`` [N m^2], secant ``GJ = T(phi) / phi`` with the twist per length
    ``phi = |th2_x - th1_x| / L0`` (tube.secant_EI, tube.secant_GJ) and the collapse flag ``kappa > kappa_collapse``;
    with ``energy`` and ``with_tangent`` the material tangent terms ``gb_out``, ``gt_out``
    (tube.secant_material_terms; else 0: ``max_end`` has no consistent tangent, and a stiffness held over a Newton
    solve is a linear law there).
    """
    for k in range(rows.shape[0]):
        e = rows[k]
        L = L0[e]
        if energy:
            s = 0.0
            for j in (1, 2):
                s += th[e, 0, j] * th[e, 0, j] + th[e, 0, j] * th[e, 1, j] + th[e, 1, j] * th[e, 1, j]
            kappa = 2.0 * math.sqrt(s) / L
        else:
            a1, a2 = -(4.0 * th[e, 0, 1] + 2.0 * th[e, 1, 1]) / L, -(4.0 * th[e, 0, 2] + 2.0 * th[e, 1, 2]) / L
            b1, b2 = (2.0 * th[e, 0, 1] + 4.0 * th[e, 1, 1]) / L, (2.0 * th[e, 0, 2] + 4.0 * th[e, 1, 2]) / L
            kappa = max(math.sqrt(a1 * a1 + a2 * a2), math.sqrt(b1 * b1 + b2 * b2))
        x = EI0[k] * kappa / M_max[k]
        EI_out[k] = EI0[k] * ((1.0 - 0.5 * x) if x < 1e-6 else -math.expm1(-x) / x)
        M_c, dM_c = 0.0, 0.0  # fold contact (tube.fold_contact)
        if kappa > kappa_fold[k]:
            a = kappa_closed[k] - kappa_fold[k]
            xf = kappa - kappa_fold[k]
            xe = _FOLD_LINEAR * a
            xi = min(xf, xe)
            u = a - xi
            M_c = M_max[k] * (xi / u) ** 2
            dM_c = M_max[k] * 2.0 * xi * a / (u * u * u)
            M_c += dM_c * max(xf - xe, 0.0)
            EI_out[k] += M_c / kappa
        y = c2[k] * abs(th[e, 1, 0] - th[e, 0, 0]) / L
        GJ_out[k] = GJ0[k] * ((1.0 - y * y / 3.0) if y < 1e-6 else math.atan(y) / y)
        collapsed_out[k] = abs(kappa) > kappa_collapse[k]
        gb_out[k], gt_out[k] = 0.0, 0.0
        if energy and with_tangent:
            if x > _SECANT_TINY:  # (EI_t - EI_s) / EI0 = exp(-x) - (1 - exp(-x)) / x, its series for small x
                dd = (-0.5 * x + x * x / 3.0 - x * x * x / 8.0) if x < 1e-4 else math.exp(-x) + math.expm1(-x) / x
                num = EI0[k] * dd + ((dM_c - M_c / kappa) if M_c > 0.0 else 0.0)
                gb_out[k] = num / (kappa * kappa * L * EI_out[k] * EI_out[k])
            if y > _SECANT_TINY:  # (GJ_t - GJ_s) / GJ0 = 1 / (1 + y^2) - atan(y) / y
                dd = (-2.0 * y * y / 3.0 + 4.0 * y ** 4 / 5.0) if y < 1e-4 else 1.0 / (1.0 + y * y) - math.atan(y) / y
                phi = y / c2[k]
                gt_out[k] = GJ0[k] * dd / (phi * phi * L * GJ_out[k] * GJ_out[k])
