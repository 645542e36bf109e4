"""The reduced-order wing's inputs and outputs, and the provenance of what is fitted (:mod:`kite_env.surrogate`).

Inputs (``INPUT_NAMES``, 30 values, SI units, frame K):

* ``q_b - q_design`` (12): A, B, C, D relative to their unloaded design positions [m],
* ``qdot_b`` (12): velocities of A, B, C, D relative to frame K [m/s] (the wing's deformation rate),
* ``v_app = v_kite - v_wind`` (3): apparent velocity of the frame origin (the air comes from ``-v_app``) [m/s],
* ``omega`` (3): rotation rate of K [rad/s].

The wing with memory adds filtered inputs (:mod:`kite_env.fitting.fit`). Outputs (``OUTPUT_NAMES``, 17 values):
``F_b`` (12, A-D x, y, z in K) [N] (the force that the bridle points exert on the wing: the wing pulls A-D with
``-F_b``), the angles of attack of the right tip, mid and left tip sections [rad], the wing's lift and drag [N].
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from kite_env.fsi import FlightState

INPUT_NAMES = tuple([f"dq_{p}{a}" for p in "ABCD" for a in "xyz"] + [f"qdot_{p}{a}" for p in "ABCD" for a in "xyz"]
                    + ["v_app_x", "v_app_y", "v_app_z", "omega_x", "omega_y", "omega_z"])
OUTPUT_NAMES = tuple([f"F_{p}{a}" for p in "ABCD" for a in "xyz"] + ["alpha_right_tip", "alpha_mid", "alpha_left_tip",
                                                                       "lift", "drag"])


def features(q_b: np.ndarray, qdot_b: np.ndarray, flight: FlightState, q_design: np.ndarray) -> np.ndarray:
    """(30,) input vector of a wing solve (module docstring)."""
    v_app = np.asarray(flight.v_kite, float) - np.asarray(flight.v_wind, float)
    return np.concatenate([(np.asarray(q_b, float) - q_design).ravel(), np.asarray(qdot_b, float).ravel(), v_app,
                           np.asarray(flight.omega, float)])


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
