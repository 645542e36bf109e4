"""Laws of the lines (Bosch et al., Sect. II.C): the bridle lines' pull-only tension, Eq. (10), in the smooth form the
Newton solves of the wing with inertia need, and the drag of straight lines and of the tether, Eq. (11). Both the
particle system (:mod:`kite_env.dynamics.particles`) and the wing with inertia (:mod:`kite_env.dynamics.wing_dynamics`)
apply them; the compiled kernels (:mod:`kite_env.dynamics.kernels`) repeat them per line.
"""

from __future__ import annotations

import numpy as np

#: width of the smoothed pull-only law of the bridle lines [N] (:func:`line_tension`)
LINE_SMOOTHING_N = 10.0


def line_tension(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pull-only line tension from the spring-damper force ``s = k_c (l - L) + c_c dl/dt`` (Eq. 10) and its
    derivative: ``T = (s + sqrt(s^2 + eps^2)) / 2`` with ``eps = LINE_SMOOTHING_N``, the smooth form of
    ``max(s, 0)`` (at most ``eps / 2`` = 5 N from it). With the wing's nodes of grams at the trailing-edge tips, a
    Newton correction of a centimetre changes the steering line's damper force by some 1000 N (``c_c gamma /
    (beta dt)`` = 10^5 N/m at 5 ms): with the kink of ``max`` the iterates flip the line between taut and slack."""
    s = np.asarray(s, dtype=float)
    eps2 = LINE_SMOOTHING_N**2
    root = np.sqrt(s * s + eps2)
    # for s < 0 the same value without the cancellation of s + root: eps^2 / (2 (root - s))
    T = np.where(s >= 0.0, 0.5 * (s + root), 0.5 * eps2 / (root - np.minimum(s, 0.0)))
    return T, 0.5 * (1.0 + s / root)


def line_drag(coef: float, va: np.ndarray, e: np.ndarray, l: np.ndarray) -> np.ndarray:
    """Drag of straight lines, Eq. (11) (n, 3) [N]: ``coef l |v_n| v_n`` with ``v_n`` the part of each line's
    apparent wind ``va`` (n, 3) normal to its direction ``e`` (n, 3), ``l`` (n,) the lengths and ``coef = -1/2 rho
    C_D d``. Half of it goes to each end."""
    van = va - np.einsum("ij,ij->i", va, e)[:, None] * e
    return coef * (l * np.sqrt(np.einsum("ij,ij->i", van, van)))[:, None] * van


def tether_drag(coef: float, r_kcu: np.ndarray, v_kcu: np.ndarray, wind_kcu: np.ndarray) -> np.ndarray:
    """The KCU's half of the optional tether drag (not in the paper's model) (3,) [N]: Eq. (11) for the tether as
    one straight line from the ground station, with the mean velocity of its ends (the ground end at rest) and the
    wind at the KCU; ``coef = -1/2 rho C_D d_t``."""
    lt = float(np.linalg.norm(r_kcu))
    et = r_kcu / lt
    vt = 0.5 * v_kcu - wind_kcu
    vtn = vt - (vt @ et) * et
    return 0.5 * (coef * lt * np.linalg.norm(vtn)) * vtn
