"""Reduced-order wing: a small MLP fitted to the full aeroelastic wing (:mod:`kite_env.fitting.fit`).

:class:`SurrogateWing` maps the 30 inputs of :data:`~kite_env.surrogate.samples.INPUT_NAMES` (and, for a wing with
memory, its filtered inputs) to the 17 outputs of :data:`~kite_env.surrogate.samples.OUTPUT_NAMES`: a tanh
multilayer perceptron on normalised inputs and outputs plus a known linear part of the bridle force (``K_b``).
Inference is plain NumPy (batched over rows) here and compiled in the fast fidelity
(:mod:`kite_env.dynamics.fast`); the weights are fitted with torch by ``kite-fit fit`` and stored as ``.npz`` with
the model they belong to (:func:`kite_env.config.fingerprint`), their provenance and the held-out errors.

Envelope: the per-input range of the training samples. :meth:`SurrogateWing.outside` names the inputs of a query
that lie more than ``margin`` times that range beyond it, so that a caller can report or refuse states far from
what the full model was sampled at.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kite_env.surrogate.samples import INPUT_NAMES, OUTPUT_NAMES

#: absolute widening of the envelope [m, m/s, rad/s]: far below any physical scale of the inputs, far above the
#: round-off of the frame transformation (about 1e-13 for a kite 80 m out); the input normalisation's floor on the
#: standard deviation (1e-6) makes such deviations invisible to the MLP
ENVELOPE_FLOOR = 1e-6


@dataclass
class SurrogateWing:
    """MLP ``y = (tanh(... tanh(x_n W_0 + b_0) ...) W_L + b_L) * y_std + y_mean`` with ``x_n = (x - x_mean) / x_std``.

    Attributes
    ----------
    weights, biases : lists of (n_in, n_out) and (n_out,) float arrays, one per layer
    x_mean, x_std : (30,) float, input normalisation
    y_mean, y_std : (17,) float, output normalisation
    x_min, x_max : (30,) float, range of the training inputs (the envelope)
    meta : dict, provenance and validation errors
    """

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    x_min: np.ndarray
    x_max: np.ndarray
    meta: dict = field(default_factory=dict)
    #: (12, 12) [N/m]: the known linear part of the bridle force, ``F_b = MLP(x) + K_b (q_b - q_design)`` (zero: all
    #: learnt; :mod:`kite_env.fitting.fit` explains why the wing with inertia's has one)
    K_b: np.ndarray = field(default_factory=lambda: np.zeros((12, 12)))

    def __post_init__(self):
        if len(self.weights) != len(self.biases) or not self.weights:
            raise ValueError("a SurrogateWing needs one bias per weight matrix and at least one layer")
        n_in = len(self.input_names)
        if self.weights[0].shape[0] != n_in or self.weights[-1].shape[1] != len(OUTPUT_NAMES):
            raise ValueError(f"layer shapes {[w.shape for w in self.weights]} do not map {n_in} inputs "
                             f"to {len(OUTPUT_NAMES)} outputs")

    @property
    def taus(self) -> tuple[float, ...]:
        """Time constants [s] of the latent low-pass filters (:mod:`kite_env.fitting.fit`); () for a memoryless
        wing (the quasi-static wing's)."""
        return tuple(float(t) for t in self.meta.get("history", {}).get("taus_s", ()))

    @property
    def filtered(self) -> tuple[int, ...]:
        """Indices of the filtered inputs among :data:`INPUT_NAMES`."""
        return tuple(int(i) for i in self.meta.get("history", {}).get("filtered", ()))

    @property
    def input_names(self) -> tuple[str, ...]:
        """The MLP's inputs: :data:`INPUT_NAMES`, then for each time constant the filtered inputs minus the current
        ones."""
        return INPUT_NAMES + history_names(self.taus, self.filtered)

    @property
    def inertial(self) -> bool:
        """Fitted to the wing with inertia: its outputs are the effective wing force on Table 1's point masses at
        A-D (:mod:`kite_env.fitting.fit`), flown without the tip dampers of the quasi-static wing."""
        return bool(self.meta.get("history", {}).get("inertial", False))

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Outputs (n, 17) for inputs (n, 30) (or (17,) for (30,))."""
        x = np.asarray(x, dtype=float)
        h = (np.atleast_2d(x) - self.x_mean) / self.x_std
        last = len(self.weights) - 1
        for i, (W, b) in enumerate(zip(self.weights, self.biases)):
            h = h @ W + b
            if i < last:
                h = np.tanh(h)
        y = h * self.y_std + self.y_mean
        y[:, :12] += np.atleast_2d(x)[:, :12] @ self.K_b.T
        return y[0] if x.ndim == 1 else y

    def envelope(self, margin: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (lo, hi) (30,) of the accepted inputs: the training range widened by ``margin`` x range on each
        side and by :data:`ENVELOPE_FLOOR` (the inputs that vanish by construction, A and C in their own frame K,
        have a range of round-off only; a query's round-off must not count as leaving it)."""
        span = self.x_max - self.x_min
        return (self.x_min - margin * span - ENVELOPE_FLOOR, self.x_max + margin * span + ENVELOPE_FLOOR)

    def outside(self, x: np.ndarray, margin: float = 0.1) -> list[str]:
        """Names of the inputs of one query ``x`` beyond :meth:`envelope`."""
        x = np.asarray(x, dtype=float)
        lo, hi = self.envelope(margin)
        names = self.input_names
        return [names[i] for i in np.flatnonzero((x < lo) | (x > hi))]

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        arrays = {f"W{i}": w.astype(np.float32) for i, w in enumerate(self.weights)}
        arrays.update({f"b{i}": b.astype(np.float32) for i, b in enumerate(self.biases)})
        np.savez_compressed(path, **arrays, x_mean=self.x_mean, x_std=self.x_std, y_mean=self.y_mean,
                            y_std=self.y_std, x_min=self.x_min, x_max=self.x_max, meta=json.dumps(self.meta),
                            K_b=self.K_b,
                            input_names=np.array(self.input_names), output_names=np.array(OUTPUT_NAMES))
        return path

    @classmethod
    def load(cls, path: str | Path) -> SurrogateWing:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"surrogate weights '{path}' do not exist")
        try:
            z = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"surrogate weights '{path}' are not a readable .npz file: {exc}") from None
        with z:
            n = sum(1 for k in z.files if k.startswith("W"))
            W = [z[f"W{i}"].astype(float) for i in range(n)]
            b = [z[f"b{i}"].astype(float) for i in range(n)]
            sw = cls(W, b, z["x_mean"], z["x_std"], z["y_mean"], z["y_std"], z["x_min"], z["x_max"],
                     json.loads(str(z["meta"])), z["K_b"] if "K_b" in z.files else np.zeros((12, 12)))
            if tuple(z["input_names"]) != sw.input_names or tuple(z["output_names"]) != OUTPUT_NAMES:
                raise ValueError(f"surrogate weights '{path}' were fitted for another input/output layout")
            return sw


def filter_gain(dt: float, tau: float) -> float:
    """Gain of the latent state's filters, the exact discrete first-order low-pass over one step:
    ``z <- z + c (x - z)``, ``c = 1 - exp(-dt/tau)``."""
    return 1.0 - math.exp(-dt / tau)


def history_names(taus, filtered) -> tuple[str, ...]:
    """Names of the latent state's inputs: each filtered input of :data:`INPUT_NAMES` per time constant [s]."""
    return tuple(f"{INPUT_NAMES[i]}_lag{int(round(1000 * tau))}ms" for tau in taus for i in filtered)


def output_errors(y_true: np.ndarray, y_pred: np.ndarray) -> dict:
    """Per-output RMS errors [SI units] and the bridle-force error relative to the mean traction: the RMS over
    samples and the 12 force components of the error, over the mean of ``|sum of F_b|`` (the wing's pull)."""
    err = np.asarray(y_pred, float) - np.asarray(y_true, float)
    rms = np.sqrt(np.mean(err**2, axis=0))
    traction = float(np.mean(np.linalg.norm(np.asarray(y_true)[:, :12].reshape(-1, 4, 3).sum(axis=1), axis=1)))
    force_rms = float(np.sqrt(np.mean(err[:, :12] ** 2)))
    return {"rms": {name: float(v) for name, v in zip(OUTPUT_NAMES, rms)}, "mean_traction_N": traction,
            "force_rms_N": force_rms, "force_rms_rel_traction": force_rms / traction}
