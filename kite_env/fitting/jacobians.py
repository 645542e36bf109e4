"""The static aeroelastic wing's force derivatives at recorded states: targets for the reduced-order wing's slopes.

Recorded flights fix the reduced-order wing's force at the states flown, but hardly how that force changes with the
angle of attack: in every flight the force loop (Eq. 19) moves the common steering length, hence the wing's pitch,
from the force ratio, so pitch and load move together and a fit cannot tell cause from effect (closed-loop
identification; Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, Ch. 13). At recorded states of
the full model's flights the shipped wing's force changes with a rigid pitch of the inflow 1.7-2.6 times as much as
the static FE wing's (docs/fast_fidelity.md, "The wing's slopes").

The wing with inertia and the static aeroelastic wing are one structure and one load model; slowly changed, the
former's force follows the latter's. So the static wing's derivatives at a recorded state are the low-frequency
(steady-state) derivatives of the effective wing force there:

* ``dF_b / dq_b`` (12 x 12): :meth:`kite_env.fsi.AeroelasticWing.bridle_stiffness`, the condensed tangent of the
  structure and the aero load with A-D prescribed (what the known linear part ``K_b`` holds at one state only);
* ``dF_b / dv_app`` (12 x 3): central differences of the static solve in the apparent velocity (frame K), its
  direction being the angle of attack and sideslip;
* ``dF_b / domega`` (12 x 3): central differences in the rotation rate of K, which the static wing's sections see as
  inflow (Eq. 2's ``omega x r``): its quasi-steady aerodynamic damping.

:func:`fitting.fit.fit_mlp` fits the MLP's derivatives with respect to its *current* inputs (the latent filters held:
at a steady state the filtered inputs move with the current ones, so their differences ``z - x`` stay) to these,
beside the forces ("Sobolev training": Czarnecki, Osindero, Jaderberg, Swirszcz & Pascanu, "Sobolev training for
neural networks", NeurIPS 2017).

Each tape ``DIR/ep_XXXX.npz`` gets ``DIR/jacobians/ep_XXXX.npz``: the rows, the derivatives and the static wing's
force there (as a check: it lies within some per cent of the recorded effective force), with the model they belong
to.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

#: the inputs (indices into :data:`kite_env.surrogate.samples.INPUT_NAMES`) whose derivatives are targets: the
#: bridle points' deformation (12), the apparent velocity (3) and the rotation rate (3)
JAC_INPUTS = tuple(range(12)) + (24, 25, 26, 27, 28, 29)
#: central-difference step of the apparent velocity [m/s] (0.5 deg of inflow angle at 30 m/s)
DV_MPS = 0.25
#: central-difference step of the rotation rate [rad/s] (0.25 m/s at the tips, 5 m from the origin)
DOMEGA_RPS = 0.05


def tape_jacobians(arrays: dict, meta: dict, cfg, wing, every: int) -> dict:
    """Derivatives of the static wing's ``F_b`` (frame K) at every ``every``-th row of one tape.

    Returns ``{"rows" (m,), "inputs" (m, 30 + history) the reduced-order wing's inputs there, "J" (m, 12, 18)
    [N/m, N s/m, N s/rad] with columns :data:`JAC_INPUTS`, "F_static" (m, 12), "failed" int}``. A state where the
    static solve does not converge (a luffing or stalled wing, a slack line) is skipped and counted: the static wing
    has no equilibrium there, so it gives no slope."""
    from kite_env.fitting.fit import latent_features, tape_samples
    from kite_env.fsi import FlightState, WingConvergenceError

    q0 = wing.design_bridle
    tips = (float(np.linalg.norm(q0[0] - q0[1])), float(np.linalg.norm(q0[2] - q0[3])))
    X, _, ok = tape_samples(arrays, cfg, q0, tips)
    H = latent_features(X, cfg.dynamics.dt_s)
    rows, Js, Fs, failed = [], [], [], 0
    warm = False
    for k in range(0, len(X), every):
        if not ok[k]:
            continue
        x = X[k]
        q_b = q0 + x[:12].reshape(4, 3)
        v_app, om = x[24:27], x[27:30]

        def flight(v, w=om):
            return FlightState(v_kite=np.asarray(v, float), omega=np.asarray(w, float), v_wind=np.zeros(3))

        try:
            sol = None
            if warm:
                try:
                    sol = wing.solve(q_b, flight(v_app), dt=None, support="prescribed", warm=True, commit=True)
                except WingConvergenceError:
                    sol = None
            if sol is None:
                # from the unloaded wing: the static equilibrium at the design bridle in this inflow, then the state
                wing.reset()
                wing.solve(None, flight(v_app), dt=None, support="prescribed", warm=False, commit=True)
                sol = wing.solve(q_b, flight(v_app), dt=None, support="prescribed", warm=True, commit=True)
            F0 = np.asarray(sol.F_b, float).ravel()
            J = np.empty((12, len(JAC_INPUTS)))
            J[:, :12] = wing.bridle_stiffness()
            for j in range(6):
                h = DV_MPS if j < 3 else DOMEGA_RPS
                d = np.zeros(3)
                d[j % 3] = h
                plus, minus = ((v_app + d, om), (v_app - d, om)) if j < 3 else ((v_app, om + d), (v_app, om - d))
                Fp = np.asarray(wing.solve(q_b, flight(*plus), dt=None, support="prescribed", warm=True,
                                           commit=False).F_b, float).ravel()
                Fm = np.asarray(wing.solve(q_b, flight(*minus), dt=None, support="prescribed", warm=True,
                                           commit=False).F_b, float).ravel()
                J[:, 12 + j] = (Fp - Fm) / (2.0 * h)
            warm = True
        except WingConvergenceError:
            failed += 1
            warm = False
            continue
        rows.append(k)
        Js.append(J)
        Fs.append(F0)
    rows = np.asarray(rows, dtype=np.int64)
    return {"rows": rows, "inputs": np.hstack([X, H])[rows], "J": np.asarray(Js).reshape(-1, 12, len(JAC_INPUTS)),
            "F_static": np.asarray(Fs).reshape(-1, 12), "failed": failed}


def jacobian_path(tape: Path) -> Path:
    return tape.parent / "jacobians" / tape.name


def compute_jacobians(tapes, cfg, every_s: float = 1.0, log=print) -> int:
    """:func:`tape_jacobians` of each of the ``tapes`` (paths, :func:`kite_env.fitting.trajectories.tape_paths`) that
    has none yet, every ``every_s`` seconds of flight; written to ``jacobians/`` beside the tapes (atomically, one
    file per tape). Returns the number of tapes done."""
    from kite_env.config import check_model, fingerprint
    from kite_env.fitting.trajectories import load_tape
    from kite_env.fsi import nominal_wing

    wing = nominal_wing(cfg.kite.name, cfg)
    every = max(1, round(every_s / cfg.dynamics.dt_s))
    done = 0
    for path in map(Path, tapes):
        out = jacobian_path(path)
        if out.exists():
            continue
        arrays, meta = load_tape(path)
        check_model(meta.get("model"), cfg, f"tape '{path}'")
        t0 = time.perf_counter()
        res = tape_jacobians(arrays, meta, cfg, wing, every)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".part.npz")
        np.savez_compressed(tmp, rows=res["rows"], inputs=res["inputs"], J=res["J"], F_static=res["F_static"],
                            meta=json.dumps({"model": fingerprint(cfg), "tape": path.name,
                                             "index": meta["plan"]["index"], "every": every,
                                             "dv_mps": DV_MPS, "domega_rps": DOMEGA_RPS, "inputs": list(JAC_INPUTS),
                                             "failed": res["failed"]}))
        tmp.replace(out)
        done += 1
        log(f"{path.name}: {len(res['rows'])} states, {res['failed']} without a static equilibrium, "
            f"{time.perf_counter() - t0:.0f} s")
    return done


def load_jacobians(tape_dir: str | Path, cfg, indices=None) -> dict | None:
    """The derivatives of ``DIR/jacobians/ep_*.npz`` whose tape's episode index is in ``indices`` (the tapes of
    the fit; None: all): ``{"inputs" (m, n_in), "J" (m, 12, 18), "group" (m,) episode index}``, or None where there
    are none."""
    from kite_env.config import check_model
    from kite_env.fitting.trajectories import tape_paths

    keep = None if indices is None else set(int(i) for i in indices)
    X, Js, G = [], [], []
    for f in tape_paths(Path(tape_dir) / "jacobians"):
        with np.load(f, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if keep is not None and int(meta["index"]) not in keep:
                continue
            check_model(meta.get("model"), cfg, f"jacobians '{f}'")
            if tuple(meta["inputs"]) != JAC_INPUTS:
                raise ValueError(f"jacobians '{f}' hold other inputs' derivatives ({meta['inputs']})")
            X.append(z["inputs"])
            Js.append(z["J"])
            G.append(np.full(len(z["rows"]), int(meta["index"])))
    if not X:
        return None
    return {"inputs": np.vstack(X), "J": np.concatenate(Js), "group": np.concatenate(G)}
