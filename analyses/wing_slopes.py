"""How the reduced-order wing's force changes with its inputs, against the static aeroelastic wing's, at recorded
states of the full model (``kite-fit slopes``; docs/fast_fidelity.md, "The wing's slopes").

For each direction of :data:`kite_env.fitting.fit.SLOPE_DIRECTIONS` (the bridle points' deformations that keep frame
K, the apparent velocity, the rotation rate) and each state: the derivative of the 12 bridle-force components, the
static wing's from its solve there (``DIR/jacobians``) and the reduced-order wing's (its MLP's tangent at the state,
latent filters held, plus its known linear part). Prints, per direction, the median over the states of the static
wing's norm, the reduced-order wing's and their difference relative to the static wing's; then the lift slope (the
total force normal to the chord per m/s of the apparent velocity's normal component) of both.

    .venv/bin/python analyses/wing_slopes.py --tapes runs/tapes [--surrogate FILE.npz ...] [--held-out]

``--held-out``: only the tapes the fit held out (every fifth episode).
"""

from __future__ import annotations

import argparse

import numpy as np


def wing_slopes(wing, X: np.ndarray) -> np.ndarray:
    """(m, d, 12) derivatives of the wing's bridle force along :func:`kite_env.fitting.fit.slope_directions` at the
    inputs ``X`` (m, n_in): the MLP's tangent (forward mode through the tanh layers) plus the known linear part."""
    from kite_env.fitting.fit import slope_directions

    U = slope_directions(X.shape[1])
    h = (X - wing.x_mean) / wing.x_std
    T = np.broadcast_to(U / wing.x_std, (len(X), *U.shape)).copy()
    last = len(wing.weights) - 1
    for i, (W, b) in enumerate(zip(wing.weights, wing.biases)):
        h = h @ W + b
        T = T @ W
        if i < last:
            h = np.tanh(h)
            T = T * (1.0 - h * h)[:, None, :]
    return T[:, :, :12] * wing.y_std[:12] + (U[:, :12] @ wing.K_b.T)[None]


def main() -> None:
    from kite_env.config import load_config
    from kite_env.fitting.fit import SLOPE_DIRECTIONS, slope_directions
    from kite_env.fitting.jacobians import JAC_INPUTS, load_jacobians
    from kite_env.surrogate import default_surrogate_path
    from kite_env.surrogate.model import SurrogateWing

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tapes", required=True)
    p.add_argument("--surrogate", action="append", default=None, help="weights (.npz); default: the shipped wing")
    p.add_argument("--held-out", action="store_true")
    args = p.parse_args()
    cfg = load_config(None)
    s = load_jacobians(args.tapes, cfg)
    if s is None:
        raise SystemExit(f"no slopes in '{args.tapes}/jacobians': run kite-fit slopes --tapes {args.tapes}")
    keep = (s["group"] % 5 == 4) if args.held_out else np.ones(len(s["group"]), bool)
    X, J = s["inputs"][keep], s["J"][keep]
    U = slope_directions(X.shape[1])[:, list(JAC_INPUTS)]
    Jd = np.einsum("mij,dj->mdi", J, U)
    print(f"{len(X)} states of {len(set(s['group'][keep]))} tapes")
    for path in args.surrogate or [str(default_surrogate_path(cfg.kite.name))]:
        wing = SurrogateWing.load(path)
        Jw = wing_slopes(wing, X)
        print(f"\n{path}\n| direction | static wing | reduced-order wing | difference / static |\n|---|---:|---:|---:|")
        for d, (_, name) in enumerate(SLOPE_DIRECTIONS):
            a = np.linalg.norm(Jd[:, d], axis=1)
            b = np.linalg.norm(Jw[:, d], axis=1)
            e = np.linalg.norm(Jd[:, d] - Jw[:, d], axis=1) / np.maximum(a, 1e-9)
            unit = "N/m" if d < 6 else ("N s/m" if name.startswith("v_app") else "N s/rad")
            print(f"| {name} | {np.median(a):,.0f} {unit} | {np.median(b):,.0f} | {np.median(e):.2f} |")
        lift_fe, lift_w = Jd[:, 8, 2::3].sum(axis=1), Jw[:, 8, 2::3].sum(axis=1)
        print(f"lift slope, total z force per m/s of v_app_z: static {np.median(lift_fe):.0f}, reduced-order "
              f"{np.median(lift_w):.0f} N s/m (median ratio {np.median(lift_w / lift_fe):.2f})")


if __name__ == "__main__":
    main()
