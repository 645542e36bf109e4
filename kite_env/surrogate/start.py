"""Start table of the reduced-order wing: the wing's start state from the full model, tabulated.

The flight simulator's reset (:meth:`kite_env.dynamics.simulator.FlightSimulator.reset`) solves the FE wing
statically, held by its bridle lines, at the start state X (no rotation) and takes from it the bridle points ``q0``
(4, 3), their forces ``F_b`` (4, 3) and the tip-pair stiffness ``k_pairs`` (4,) (``start_wing``). The fast
fidelity cannot run the FE wing at every reset, so :func:`kite_env.dynamics.start_table.build_start_table` runs
exactly that path of the full model on a grid and :class:`StartTable` interpolates it.

Why two numbers suffice: the wing's loads depend on the flight state only through the apparent velocity
``v_app = v_kite - v_wind`` (Eq. 2: ``v_a^i = v_k + omega_k x r_i1 + u_i - v_w``, here with ``omega_k = 0`` and no
deformation velocity in a static solve; the wing carries no gravity load). In the frame of the start the reset
orients the nose along the tangential part of ``v_app``, so ``v_app = (-s, 0, w)`` with the tangential apparent
speed ``s > 0`` [m/s] and ``w = -v_wind . R0`` [m/s] (``R0`` the unit position of the KCU). The table depends on
the configuration (kite, aerodynamics, structure, power-line length), which it stores with its provenance.

Interpolation is bilinear in (s, w), of ``q0``, ``k_pairs`` and of ``F_b / (s^2 + w^2)`` (the aerodynamic forces
scale with the dynamic pressure, Eq. 8-9, so the scaled force varies slowly), multiplied back by the query's
``s^2 + w^2``. A grid point where the full model does not converge is stored as NaN; a query outside the grid or in
a cell with such a point raises :class:`ValueError`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

FORMAT = "kite_env.start_table/1"


@dataclass
class StartTable:
    """The wing's start on a grid of tangential apparent speed ``s`` and normal apparent velocity ``w``.

    Attributes
    ----------
    s : (n_s,) float [m/s], increasing
    w : (n_w,) float [m/s], increasing
    q0 : (n_s, n_w, 4, 3) float [m], bridle points A-D in K (NaN where the full model did not converge)
    F_b : (n_s, n_w, 4, 3) float [N], their forces in K
    k_pairs : (n_s, n_w, 4) float [N/m], tip-pair stiffness (A-C, B-D, A-D, B-C)
    meta : dict, provenance (git commit, kite, config, grid, failed points)
    """

    s: np.ndarray
    w: np.ndarray
    q0: np.ndarray
    F_b: np.ndarray
    k_pairs: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.s, self.w = np.asarray(self.s, float), np.asarray(self.w, float)
        n_s, n_w = len(self.s), len(self.w)
        if n_s < 2 or n_w < 2 or np.any(np.diff(self.s) <= 0) or np.any(np.diff(self.w) <= 0):
            raise ValueError("a StartTable needs at least 2 strictly increasing values of s and of w")
        if np.any(self.s <= 0):
            raise ValueError("the tangential apparent speeds s of a StartTable must be positive")
        for name, shape in (("q0", (n_s, n_w, 4, 3)), ("F_b", (n_s, n_w, 4, 3)), ("k_pairs", (n_s, n_w, 4))):
            arr = np.asarray(getattr(self, name), float)
            if arr.shape != shape:
                raise ValueError(f"StartTable.{name} has shape {arr.shape}, expected {shape}")
            setattr(self, name, arr)

    @property
    def converged(self) -> np.ndarray:
        """(n_s, n_w) bool: grid points where the full model converged."""
        return (np.all(np.isfinite(self.q0), axis=(2, 3)) & np.all(np.isfinite(self.F_b), axis=(2, 3))
                & np.all(np.isfinite(self.k_pairs), axis=2))

    def _range(self) -> str:
        return f"s in [{self.s[0]:g}, {self.s[-1]:g}] m/s, w in [{self.w[0]:g}, {self.w[-1]:g}] m/s"

    def lookup(self, v_app: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The start of the wing at the apparent velocity ``v_app`` (3,) [m/s] in the frame of the start.

        Returns ``q0`` (4, 3) [m], ``F_b`` (4, 3) [N] and ``k_pairs`` (4,) [N/m], interpolated bilinearly (module
        docstring). Raises :class:`ValueError` for a query with sideslip, outside the grid, or in a cell that has
        a grid point where the full model did not converge.
        """
        v = np.asarray(v_app, float).reshape(3)
        s, w = -v[0], v[2]
        if not np.all(np.isfinite(v)):
            raise ValueError(f"start table: non-finite apparent velocity {v}")
        if abs(v[1]) > 1e-6 * np.linalg.norm(v) + 1e-9:
            raise ValueError(f"start table: apparent velocity {v} has a sideways part; the reset's start has "
                             "v_app = (-s, 0, w)")
        if not (self.s[0] <= s <= self.s[-1] and self.w[0] <= w <= self.w[-1]):
            raise ValueError(f"start table: s = {s:.3f} m/s, w = {w:.3f} m/s outside the tabulated range "
                             f"({self._range()})")
        i = int(np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2))
        j = int(np.clip(np.searchsorted(self.w, w, side="right") - 1, 0, len(self.w) - 2))
        ts = (s - self.s[i]) / (self.s[i + 1] - self.s[i])
        tw = (w - self.w[j]) / (self.w[j + 1] - self.w[j])
        wgt = np.array([[(1 - ts) * (1 - tw), (1 - ts) * tw], [ts * (1 - tw), ts * tw]])  # (2, 2) corners
        ok = self.converged[i:i + 2, j:j + 2]
        if np.any((wgt > 0) & ~ok):
            bad = [(float(self.s[i + a]), float(self.w[j + b])) for a in range(2) for b in range(2)
                   if wgt[a, b] > 0 and not ok[a, b]]
            raise ValueError(f"start table: s = {s:.3f} m/s, w = {w:.3f} m/s lies next to grid point(s) (s, w) = "
                             f"{bad} where the full wing did not converge ({self._range()}; "
                             f"{int(ok.size - ok.sum())} of 4 corners missing)")
        q2 = self.s[i:i + 2, None] ** 2 + self.w[None, j:j + 2] ** 2  # (2, 2) corner s^2 + w^2

        def blend(arr, scale=None):
            c = arr[i:i + 2, j:j + 2]
            if scale is not None:
                c = c / scale.reshape(2, 2, *([1] * (c.ndim - 2)))
            c = np.where(wgt.reshape(2, 2, *([1] * (c.ndim - 2))) > 0, c, 0.0)  # unused NaN corners
            return np.einsum("ab,ab...->...", wgt, c)

        q0 = blend(self.q0)
        F_b = blend(self.F_b, q2) * (s**2 + w**2)
        k = blend(self.k_pairs)
        return q0, F_b, k

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        np.savez_compressed(path, format=FORMAT, s=self.s, w=self.w, q0=self.q0, F_b=self.F_b, k_pairs=self.k_pairs,
                            meta=json.dumps(self.meta))
        return path

    @classmethod
    def load(cls, path: str | Path) -> StartTable:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"start table '{path}' does not exist")
        try:
            z = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"start table '{path}' is not a readable .npz file: {exc}") from None
        with z:
            if "format" not in z.files or str(z["format"]) != FORMAT:
                raise ValueError(f"'{path}' is not a start table ({FORMAT})")
            return cls(z["s"], z["w"], z["q0"], z["F_b"], z["k_pairs"], json.loads(str(z["meta"])))
