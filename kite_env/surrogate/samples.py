"""Samples of the quasi-static aeroelastic wing for a reduced-order model (the fast fidelity).

The paper's wing is quasi-static: at every time step the FE wing is solved for the bridle-point positions ``q_b`` in
frame K and the wing state X = (v_kite, omega, v_wind) in K (Sect. II.A-D, Fig. 6), and returns the reaction forces
``F_b`` at A-D. A sample pairs those inputs with the outputs the flight model, the environment and the metrics use.

Inputs (``INPUT_NAMES``, 30 values, SI units, frame K):

* ``q_b - q_design`` (12): A, B, C, D relative to their unloaded design positions [m],
* ``qdot_b`` (12): velocities of A, B, C, D relative to frame K [m/s] (the wing's deformation rate, which Eq. 3
  turns into aerodynamic damping; zero for a static solve),
* ``v_app = v_kite - v_wind`` (3): apparent velocity of the frame origin (the air comes from ``-v_app``) [m/s],
* ``omega`` (3): rotation rate of K [rad/s].

Outputs (``OUTPUT_NAMES``, 17 values): ``F_b`` (12, A-D x, y, z in K) [N], the angles of attack of the right tip,
mid and left tip sections [rad], the wing's lift and drag [N].

Where samples come from (:class:`StateSampler`, attached to the environment as its recorder, and
``scripts/sample_wing.py``): the wing solutions of the full model along flights (every ``every``-th physics step;
``origin`` 0; free: the flight solved them anyway), plus ``n_perturb`` *static* solves (``dt = None``, no Eq. 3
memory, ``qdot_b = 0``; ``origin`` 1) with the inputs perturbed around each visited state, warm-started from it so
that they stay on its branch, with the perturbed bridle points made admissible (tip beams at their lengths,
expressed in the frame they define). A solve that does not converge is counted and skipped, never stored.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kite_env.frames import kite_frame
from kite_env.fsi import FlightState, WingConvergenceError

INPUT_NAMES = tuple([f"dq_{p}{a}" for p in "ABCD" for a in "xyz"] + [f"qdot_{p}{a}" for p in "ABCD" for a in "xyz"]
                    + ["v_app_x", "v_app_y", "v_app_z", "omega_x", "omega_y", "omega_z"])
OUTPUT_NAMES = tuple([f"F_{p}{a}" for p in "ABCD" for a in "xyz"] + ["alpha_right_tip", "alpha_mid", "alpha_left_tip",
                                                                       "lift", "drag"])
#: default perturbation scales (standard deviations) of the inputs around a visited state
PERTURB_SCALES = {"dq_m": 0.02, "v_app_rel": 0.08, "omega_rad_s": 0.15}


def features(q_b: np.ndarray, qdot_b: np.ndarray, flight: FlightState, q_design: np.ndarray) -> np.ndarray:
    """(30,) input vector of a wing solve (module docstring)."""
    v_app = np.asarray(flight.v_kite, float) - np.asarray(flight.v_wind, float)
    return np.concatenate([(np.asarray(q_b, float) - q_design).ravel(), np.asarray(qdot_b, float).ravel(), v_app,
                           np.asarray(flight.omega, float)])


def targets(sol) -> np.ndarray:
    """(17,) output vector of a :class:`kite_env.fsi.WingSolution` (module docstring)."""
    a = sol.alpha
    return np.concatenate([sol.F_b.ravel(), [a[0], a[len(a) // 2], a[-1], sol.lift, sol.drag]])


def admissible(q_b: np.ndarray, tip_lengths: tuple[float, float]) -> np.ndarray:
    """Bridle points ``q_b`` (4, 3) made consistent with the flight model: the tip beams A-B and C-D at their
    lengths (distance constraints; B and D moved along the tip chords) and the points expressed in the frame K they
    define (A and C on the y_k axis, the mid-point of B and D in the x_k-y_k plane)."""
    A, B, C, D = np.asarray(q_b, float)
    B = A + (B - A) * (tip_lengths[0] / np.linalg.norm(B - A))
    D = C + (D - C) * (tip_lengths[1] / np.linalg.norm(D - C))
    q = np.stack([A, B, C, D])
    origin, R = kite_frame(A, B, C, D)
    return (q - origin) @ R


def flight_state(x: np.ndarray, q_design: np.ndarray) -> tuple[np.ndarray, FlightState]:
    """Inverse of :func:`features`: ``q_b`` (4, 3) and a :class:`FlightState` with zero wind."""
    x = np.asarray(x, float)
    q_b = q_design + x[:12].reshape(4, 3)
    return q_b, FlightState(v_kite=x[24:27].copy(), omega=x[27:30].copy(), v_wind=np.zeros(3))


@dataclass
class WingSamples:
    """Inputs (n, 30) and outputs (n, 17) of static wing solves, with the origin of each sample and provenance."""

    inputs: np.ndarray
    outputs: np.ndarray
    origin: np.ndarray  # (n,) int: 0 = a visited state, 1 = a perturbation of one
    group: np.ndarray  # (n,) int: the episode a sample comes from (for held-out splits by episode)
    meta: dict = field(default_factory=dict)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        np.savez_compressed(path, inputs=self.inputs, outputs=self.outputs, origin=self.origin, group=self.group,
                            meta=json.dumps(self.meta), input_names=np.array(INPUT_NAMES),
                            output_names=np.array(OUTPUT_NAMES))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "WingSamples":
        with np.load(path, allow_pickle=False) as z:
            if tuple(z["input_names"]) != INPUT_NAMES or tuple(z["output_names"]) != OUTPUT_NAMES:
                raise ValueError(f"{path}: sample layout differs from this version's INPUT_NAMES/OUTPUT_NAMES")
            return cls(z["inputs"], z["outputs"], z["origin"], z["group"], json.loads(str(z["meta"])))

    @classmethod
    def concatenate(cls, parts: list["WingSamples"], meta: dict | None = None) -> "WingSamples":
        return cls(np.concatenate([p.inputs for p in parts]), np.concatenate([p.outputs for p in parts]),
                   np.concatenate([p.origin for p in parts]), np.concatenate([p.group for p in parts]),
                   dict(meta or {}))

    @classmethod
    def merge(cls, parts: list["WingSamples"]) -> "WingSamples":
        """The samples of separate sampling runs as one set: episode labels renumbered so that every run's
        episodes stay distinct (the hold-out split is by episode); meta: the first run's, with every run's under
        ``runs`` and the total ``n_samples`` and ``episodes``."""
        if not parts:
            raise ValueError("nothing to merge")
        shifted, offset = [], 0
        for p in parts:
            shifted.append(cls(p.inputs, p.outputs, p.origin, p.group + offset, p.meta))
            offset += int(p.group.max()) + 1 if p.group.size else 0
        meta = dict(parts[0].meta)
        meta.update({"runs": [p.meta for p in parts], "n_samples": int(sum(len(p.inputs) for p in parts)),
                     "episodes": offset})
        return cls.concatenate(shifted, meta)


class StateSampler:
    """Environment recorder (``env.recorder``) that solves the wing statically at visited states and around them.

    Parameters
    ----------
    every : int
        Sample every ``every``-th physics step of the flight.
    n_perturb : int
        Perturbed static solves per visited state.
    rng : numpy Generator
        Draws the perturbations (same seed, same samples).
    group : int
        Episode label stored with the samples.
    scales : dict
        Perturbation standard deviations (``PERTURB_SCALES``).
    """

    def __init__(self, every: int, n_perturb: int, rng: np.random.Generator, group: int = 0,
                 scales: dict | None = None):
        self.every = max(1, int(every))
        self.n_perturb = int(n_perturb)
        self.rng = rng
        self.group = int(group)
        self.scales = dict(PERTURB_SCALES if scales is None else scales)
        self.X: list[np.ndarray] = []
        self.Y: list[np.ndarray] = []
        self.origin: list[int] = []
        self.failed = 0
        self._k = 0

    # the recorder interface of KiteFigureEightEnv
    def start(self, sim, rec, s0, L_B, L_D, mu) -> None:
        self.sim = sim
        self.q_design = sim.wing.design_bridle
        self._k = 0
        self._sample(rec)

    def record(self, rec, L_B, L_D, ainfo, t_step) -> None:
        self._k += 1
        if self._k % self.every == 0:
            self._sample(rec)

    def _solve(self, q_b, flight) -> np.ndarray | None:
        try:
            sol = self.sim.wing.solve(q_b, flight, dt=None, support="prescribed", warm=True, commit=False)
        except WingConvergenceError:
            self.failed += 1
            return None
        return targets(sol)

    def _sample(self, rec) -> None:
        r, v = rec.state.r, rec.state.v
        origin, R = kite_frame(r[0], r[1], r[2], r[3])
        q_b = (r[:4] - origin) @ R
        w_K = R.T @ rec.omega
        qdot_b = (v[:4] - rec.v_kite) @ R - np.cross(w_K, q_b)  # velocity relative to the rotating frame K
        flight = FlightState(v_kite=R.T @ rec.v_kite, omega=w_K, v_wind=R.T @ rec.v_wind)
        base = features(q_b, qdot_b, flight, self.q_design)
        self.X.append(base)
        self.Y.append(targets(rec.wing))
        self.origin.append(0)
        sc = self.scales
        for _ in range(self.n_perturb):
            x = base.copy()
            x[:12] += self.rng.normal(0.0, sc["dq_m"], 12)
            x[12:24] = 0.0
            x[24:27] *= 1.0 + self.rng.normal(0.0, sc["v_app_rel"], 3)
            x[27:30] += self.rng.normal(0.0, sc["omega_rad_s"], 3)
            qp, fp = flight_state(x, self.q_design)
            qp = admissible(qp, self.sim.tip_lengths)
            x[:12] = (qp - self.q_design).ravel()
            yp = self._solve(qp, fp)
            if yp is not None:
                self.X.append(x)
                self.Y.append(yp)
                self.origin.append(1)

    def samples(self) -> WingSamples:
        n = len(self.X)
        return WingSamples(np.array(self.X).reshape(n, len(INPUT_NAMES)), np.array(self.Y).reshape(n, len(OUTPUT_NAMES)),
                           np.array(self.origin, dtype=int), np.full(n, self.group, dtype=int))


def git_commit(repo: str | Path | None = None) -> str:
    """The current git commit of the project (``unknown`` outside a checkout), for the provenance of samples."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo or Path(__file__).resolve().parents[2],
                             capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=repo or Path(__file__).resolve().parents[2],
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if out.returncode != 0:
        return "unknown"
    return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
