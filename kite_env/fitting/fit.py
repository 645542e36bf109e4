"""Fit the reduced-order wing of the wing with inertia to recorded flights (:mod:`kite_env.fitting.trajectories`).

The fast fidelity keeps the paper's particle system (Sect. II.C: A, B, C, D with Table 1's point masses, the KCU, the
bridle lines, the tether and the tip constraints) and replaces the FE wing by a learned force on A-D. For the wing
with inertia that force is the *effective* wing force: whatever makes Table 1's point masses at A-D move as the FE
wing's nodes A-D move,

    F_wing,i = m_i a_i - f_i(r, v, wind)        (i = A, B, C, D),

with ``a_i`` the FE wing's node accelerations and ``f_i`` the particle system's applied forces without the wing
(bridle lines, Eq. 10; their drag, Eq. 11; gravity; :meth:`ParticleSystem.forces`). It holds the aerodynamic load,
the pull of the rest of the wing's structure and the inertia of its distributed and added mass. The tip constraints'
forces lie along A-B and C-D; the FE wing's tips keep their lengths to within millimetres, so the constrained fast
model reproduces these accelerations with multipliers near zero.

The wing with inertia answers with a lag (its structure and added mass, a 4 Hz lowest mode): the force at a time
depends on the recent motion. The reduced-order wing carries that memory as a small latent state: first-order
low-pass filters of its inputs with time constants :data:`TAUS` (a Laguerre/Wiener-type model: linear filters of
the input followed by a static nonlinearity, Wahlberg, "System identification using Laguerre models", IEEE TAC
36(5), 1991), updated once per physics step, exactly as :func:`latent_update` does in the flight kernel. Its MLP sees
the current inputs (:data:`kite_env.surrogate.samples.INPUT_NAMES`, frame K) and, for each time constant, the
difference between the filtered inputs :data:`FILTERED` and their current values.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kite_env.surrogate.model import filter_gain

#: the sections' angles of attack are fitted within +-ALPHA_BOUND [rad]: beyond it a section is stalled or, on a kite
#: that falls back on a slack tether, blown from behind (alpha jumps by 2 pi at the rear); the reduced-order wing
#: reports the bound there (its angles are diagnostics: the forces do not use them)
ALPHA_BOUND = 0.5
#: time constants of the latent low-pass filters [s]
TAUS = (0.05, 0.25)
#: the inputs that are filtered: the bridle points' deformation, the apparent velocity and the rotation rate
FILTERED = tuple(list(range(12)) + list(range(24, 30)))


def history_names(taus=TAUS) -> tuple[str, ...]:
    """Names of the latent state's inputs with these time constants (:func:`kite_env.surrogate.model.history_names`)."""
    from kite_env.surrogate.model import history_names as names

    return names(taus, FILTERED)


def latent_features(X: np.ndarray, dt: float, taus=TAUS) -> np.ndarray:
    """History inputs (n, len(taus) * len(FILTERED)) along one recorded flight ``X`` (n, 30): per step the filters are
    updated with the new inputs, then ``z - x``; the filters start at the first row's inputs (a steady start)."""
    sel = np.asarray(FILTERED)
    out = np.empty((len(X), len(taus) * len(sel)))
    for j, tau in enumerate(taus):
        c = filter_gain(dt, tau)
        z = X[0, sel].copy()
        for k in range(len(X)):
            z += c * (X[k, sel] - z)
            out[k, j * len(sel):(j + 1) * len(sel)] = z - X[k, sel]
    return out


def tape_samples(arrays: dict, cfg, q_design: np.ndarray, tip_lengths, accel: str = "central"):
    """Inputs (n, 30) and outputs (n, 17) along one tape, and the rows where both are defined.

    ``accel``: the accelerations of A-D in the effective force, ``"wing"`` the FE wing's own (generalized-alpha,
    end of the step; it carries the numerical oscillation of the scheme), ``"central"`` the central difference of
    the recorded velocities over two steps (what the fast model's RK4 integrates; default)."""
    from kite_env.dynamics.fast import kite_inputs
    from kite_env.dynamics.particles import ParticleSystem

    n = len(arrays["t"])
    ps = ParticleSystem(cfg.dynamics, tip_lengths, np.zeros(4), cfg.aero.rho_kg_m3)
    X = np.zeros((n, 30))
    Y = np.full((n, 17), np.nan)
    wf, wi = np.zeros(9), np.zeros(2, dtype=np.int64)
    wv, ph, om, amp = np.zeros((3, 3)), np.zeros(3), np.zeros(3), np.zeros(3)
    wind5, R, pos, w6, t_buf = np.empty((5, 3)), np.empty((3, 3)), np.empty((6, 3)), np.empty((6, 3)), np.empty(1)
    r, v, wind = arrays["r"], arrays["v"], arrays["wind"]
    if accel == "wing":
        a = arrays["a"]
    else:
        a = np.full_like(v, np.nan)
        a[1:-1] = (v[2:] - v[:-2]) / (arrays["t"][2:] - arrays["t"][:-2])[:, None, None]
    for k in range(n):
        turb6 = np.ascontiguousarray(wind[k])
        kite_inputs(float(arrays["t"][k]), r[k], v[k], q_design, wf, wi, wv, ph, om, amp, 1, X[k], wind5, R, pos,
                    w6, t_buf, turb6, True)
        ps.set_steering(float(arrays["rest"][k, 1]), float(arrays["rest"][k, 3]))
        f, _ = ps.forces(r[k], v[k], wind[k, :5], np.zeros((4, 3)))
        F_w = ps.m[:4, None] * a[k, :4] - f[:4]
        Y[k, :12] = -(F_w @ R).ravel()  # the reaction F_b = -F_wing in K (the static wing's layout: F_k = -F_b on A-D)
        Y[k, 12:15] = np.clip(arrays["alpha"][k], -ALPHA_BOUND, ALPHA_BOUND)
        Y[k, 15], Y[k, 16] = arrays["lift"][k], arrays["drag"][k]
    ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Y), axis=1)
    return X, Y, ok


@dataclass
class FitData:
    inputs: np.ndarray  # (n, 30 + history)
    outputs: np.ndarray  # (n, 17)
    group: np.ndarray  # (n,) episode index
    meta: dict


def build_dataset(tape_dir: str | Path, cfg, wing, taus=TAUS, accel: str = "central", every: int = 1,
                  log=print) -> FitData:
    """All tapes of ``tape_dir`` as one data set (every ``every``-th row; the history along every row)."""
    from kite_env.config import check_model
    from kite_env.fitting.trajectories import load_tape, tape_paths

    log(f"reading the tapes of '{tape_dir}'")
    q0 = wing.design_bridle
    tips = (float(np.linalg.norm(q0[0] - q0[1])), float(np.linalg.norm(q0[2] - q0[3])))
    Xs, Ys, G, eps = [], [], [], []
    t0 = time.perf_counter()
    for path in tape_paths(tape_dir):
        arrays, meta = load_tape(path)
        check_model(meta.get("model"), cfg, f"tape '{path}'")
        X, Y, ok = tape_samples(arrays, cfg, q0, tips, accel)
        H = latent_features(X, cfg.dynamics.dt_s, taus)
        keep = ok.copy()
        keep[np.arange(len(keep)) % every != 0] = False
        Xs.append(np.hstack([X, H])[keep])
        Ys.append(Y[keep])
        G.append(np.full(int(keep.sum()), meta["plan"]["index"]))
        eps.append({"index": meta["plan"]["index"], "policy": meta["plan"]["policy"], "end": meta["end"],
                    "flown_s": meta["flown_s"], "wind_mps": meta["plan"]["wind_mps"]})
    if not Xs:
        raise FileNotFoundError(f"no tapes (ep_*.npz) in '{tape_dir}'")
    log(f"{len(Xs)} tapes, {sum(len(x) for x in Xs)} rows in {time.perf_counter() - t0:.0f} s")
    return FitData(np.vstack(Xs), np.vstack(Ys), np.concatenate(G),
                   {"episodes": eps, "taus_s": list(taus), "accel": accel, "every": every})


def _q(point: str, axis: str) -> int:
    return "ABCD".index(point) * 3 + "xyz".index(axis)


#: the directions of the wing's slopes fitted with ``slopes`` (rows: weights on :data:`kite_env.surrogate.samples.
#: INPUT_NAMES`' first 30; names): the bridle points' deformations that keep frame K (A and C stay on its y axis
#: symmetric about the origin, the midpoint of B and D in its x-y plane: :func:`kite_env.frames.kite_frame`; any
#: other change of q_b also moves K, and the inputs, which are in K, cannot take it), the apparent velocity and the
#: rotation rate
SLOPE_DIRECTIONS: tuple[tuple[dict[int, float], str], ...] = (
    ({_q("A", "y"): 1.0, _q("C", "y"): -1.0}, "span"),
    ({_q("B", "x"): 1.0}, "B_x"), ({_q("B", "y"): 1.0}, "B_y"),
    ({_q("D", "x"): 1.0}, "D_x"), ({_q("D", "y"): 1.0}, "D_y"),
    ({_q("B", "z"): 1.0, _q("D", "z"): -1.0}, "twist"),
    ({24: 1.0}, "v_app_x"), ({25: 1.0}, "v_app_y"), ({26: 1.0}, "v_app_z"),
    ({27: 1.0}, "omega_x"), ({28: 1.0}, "omega_y"), ({29: 1.0}, "omega_z"),
)


def slope_indices(names) -> list[int]:
    """Indices into :data:`SLOPE_DIRECTIONS` of the directions named (None: all); an unknown name is a ValueError
    naming it."""
    known = [n for _, n in SLOPE_DIRECTIONS]
    if names is None:
        return list(range(len(known)))
    bad = [n for n in names if n not in known]
    if bad or not names:
        raise ValueError(f"unknown slope direction(s) {bad or names}; known: {', '.join(known)}")
    return [known.index(n) for n in names]


def slope_directions(n_in: int, names=None) -> np.ndarray:
    """(d, n_in) the directions of :data:`SLOPE_DIRECTIONS` (those named in ``names``; None: all) in the raw inputs
    (only current inputs: the latent filters' differences ``z - x`` stay, as at a steady state)."""
    picked = slope_indices(names)
    U = np.zeros((len(picked), n_in))
    for d, k in enumerate(picked):
        for i, v in SLOPE_DIRECTIONS[k][0].items():
            U[d, i] = v
    return U


def _direction_scale(x_std: np.ndarray, names=None) -> np.ndarray:
    """(d,) the length of each direction: one standard deviation of its first input over the samples."""
    return np.array([x_std[next(iter(SLOPE_DIRECTIONS[k][0]))] for k in slope_indices(names)])


def slope_tangents(x_std: np.ndarray, n_in: int, names=None) -> np.ndarray:
    """(d, n_in) the directions in normalised inputs, each one standard deviation of its first input long."""
    return slope_directions(n_in, names) * _direction_scale(x_std, names)[:, None] / x_std[None, :]


def slope_targets(slopes: dict, K_b, x_mean, x_std, y_std, holdout: int, names=None):
    """The normalised slope targets of the MLP: ``(inputs (m, n_in) normalised, targets (m, d, 12), held_out (m,))``,
    the static wing's derivatives along the directions less the known linear part's, per direction length
    (:func:`slope_tangents`) and per output standard deviation."""
    from kite_env.fitting.jacobians import JAC_INPUTS

    X = slopes["inputs"]
    U = slope_directions(X.shape[1], names)[:, list(JAC_INPUTS)]  # (d, len(JAC_INPUTS))
    T = np.einsum("mij,dj->mdi", slopes["J"], U)
    if K_b is not None:
        T = T - (U[:, :12] @ np.asarray(K_b).T)[None, :, :]
    T = T * _direction_scale(x_std, names)[None, :, None] / y_std[None, None, :12]
    return (X - x_mean) / x_std, T, (slopes["group"] % holdout) == holdout - 1


def fit_mlp(data: FitData, hidden=(64, 64), epochs: int = 200, batch: int = 2048, lr: float = 2e-3,
            holdout: int = 5, seed: int = 0, K_b: np.ndarray | None = None, slopes: dict | None = None,
            slope_weight: float = 0.0, slope_names=None, log=print):
    """Fit a tanh MLP (normalised inputs and outputs, Adam, mini-batches, the learning rate halved on a plateau of
    the held-out loss; the epoch with the lowest held-out loss kept) to the outputs less the known linear part
    ``K_b (q_b - q_design)`` of the bridle force. Every ``holdout``-th episode is held out. Returns
    ``(weights, biases, norms, report)``; the report's errors are those of the whole model (MLP and linear part).

    ``slopes`` (:func:`kite_env.fitting.jacobians.load_jacobians`) with ``slope_weight`` > 0 adds the wing's slopes
    to the loss: the bridle force's derivatives along :data:`SLOPE_DIRECTIONS` at those states against the static
    wing's (:mod:`kite_env.fitting.jacobians`), each per standard deviation of its input over the samples and per
    standard deviation of the force, weighed ``slope_weight`` against the forces' mean square; ``slope_names``: only
    the directions of these names (None: all)."""
    import torch

    torch.manual_seed(seed)
    X, Y_all, g = data.inputs, data.outputs, data.group
    lin = np.zeros_like(Y_all)
    if K_b is not None:
        lin[:, :12] = X[:, :12] @ np.asarray(K_b).T
    Y = Y_all - lin
    val = (g % holdout) == holdout - 1
    x_mean, x_std = X[~val].mean(0), X[~val].std(0) + 1e-6
    y_mean, y_std = Y[~val].mean(0), Y[~val].std(0) + 1e-9
    xt = torch.tensor((X - x_mean) / x_std, dtype=torch.float32)
    yt = torch.tensor((Y - y_mean) / y_std, dtype=torch.float32)
    sizes = [X.shape[1], *hidden, Y.shape[1]]
    layers: list = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.Tanh())
    net = torch.nn.Sequential(*layers)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=10)
    vm = torch.from_numpy(val)
    x_tr, y_tr, x_va, y_va = xt[~vm], yt[~vm], xt[vm], yt[vm]
    use_slopes = slopes is not None and slope_weight > 0.0
    if use_slopes:
        assert slopes is not None
        sx, sT, sval = slope_targets(slopes, K_b, x_mean, x_std, y_std, holdout, slope_names)
        sx_t, sT_t = torch.tensor(sx, dtype=torch.float32), torch.tensor(sT, dtype=torch.float32)
        svm = torch.from_numpy(sval)
        s_tr, sT_tr, s_va, sT_va = sx_t[~svm], sT_t[~svm], sx_t[svm], sT_t[svm]
        dirs = torch.tensor(slope_tangents(x_std, X.shape[1], slope_names), dtype=torch.float32)  # (d, n_in)
        s_batch = max(1, round(batch * len(s_tr) / max(1, len(x_tr)) * 8))
        log(f"slopes: {len(s_tr)} states in the fit, {len(s_va)} held out, {len(dirs)} directions each, "
            f"{s_batch} states per batch, weight {slope_weight}")

    def slope_loss(xs, Ts):
        """Mean square of the normalised slope error at the states ``xs`` (m, n_in) against ``Ts`` (m, d, 12)."""
        h = xs
        T = dirs.unsqueeze(0).expand(len(xs), -1, -1)
        for m in net:
            if isinstance(m, torch.nn.Linear):
                h = m(h)
                T = T @ m.weight.T
            else:
                h = torch.tanh(h)
                T = T * (1.0 - h * h).unsqueeze(1)
        return torch.mean((T[:, :, :12] - Ts) ** 2)

    gen = torch.Generator().manual_seed(seed)
    best = (float("inf"), None, -1)
    best_parts = (float("nan"), float("nan"))
    t0 = time.perf_counter()
    for epoch in range(epochs):
        order = torch.randperm(len(x_tr), generator=gen)
        for k in range(0, len(x_tr), batch):
            idx = order[k:k + batch]
            opt.zero_grad()
            loss = torch.mean((net(x_tr[idx]) - y_tr[idx]) ** 2)
            if use_slopes:
                sidx = torch.randint(len(s_tr), (s_batch,), generator=gen)
                loss = loss + slope_weight * slope_loss(s_tr[sidx], sT_tr[sidx])
            loss.backward()
            opt.step()
        with torch.no_grad():
            lf = float(torch.mean((net(x_va) - y_va) ** 2))
            ls = float(slope_loss(s_va, sT_va)) if use_slopes and len(s_va) else 0.0
        lv = lf + slope_weight * ls
        sched.step(lv)
        if lv < best[0]:
            best = (lv, [p.detach().clone() for p in net.parameters()], epoch)
            best_parts = (lf, ls)
        if epoch % 10 == 0 or epoch == epochs - 1:
            log(f"epoch {epoch:4d}  held-out loss {lv:.5f} (forces {lf:.5f}, slopes {ls:.4f})  best {best[0]:.5f} "
                f"({best[2]})  lr {opt.param_groups[0]['lr']:.1e}  {time.perf_counter() - t0:.0f} s")
        if opt.param_groups[0]["lr"] < lr / 64:
            break
    with torch.no_grad():
        for p, b in zip(net.parameters(), best[1]):
            p.copy_(b)
        pred = net(x_va).numpy() * y_std + y_mean + lin[val]
    W = [m.weight.detach().numpy().T.astype(np.float64) for m in net if isinstance(m, torch.nn.Linear)]
    b = [m.bias.detach().numpy().astype(np.float64) for m in net if isinstance(m, torch.nn.Linear)]
    from kite_env.surrogate.model import output_errors

    report = output_errors(Y_all[val], pred)
    report.update({"best_epoch": best[2], "held_out_loss": best[0], "held_out_force_loss": best_parts[0],
                   "held_out_slope_loss": best_parts[1] if use_slopes else None, "slope_weight": slope_weight,
                   "slope_directions": ([SLOPE_DIRECTIONS[k][1] for k in slope_indices(slope_names)]
                                        if use_slopes else None),
                   "fit_s": time.perf_counter() - t0,
                   "n_train": int((~val).sum()), "n_val": int(val.sum()), "hidden": list(hidden), "seed": seed,
                   "holdout": holdout, "epochs": epochs, "lr": lr, "batch": batch})
    lo, hi = X[~val].min(0), X[~val].max(0)
    return W, b, (x_mean, x_std, y_mean, y_std, lo, hi), report


__all__ = ["FILTERED", "FitData", "TAUS", "build_dataset", "filter_gain", "fit_mlp", "history_names",
           "latent_features", "tape_samples"]


def reference_stiffness(cfg, wing=None) -> np.ndarray:
    """The known linear part of the reduced-order wing's bridle force: the condensed stiffness ``dF_b/dq_b`` (12, 12)
    [N/m] of the static aeroelastic wing (:meth:`kite_env.fsi.AeroelasticWing.bridle_stiffness`: the structure's
    tangent with the aerodynamic load's Jacobian, the bridle points prescribed) at the paper's start (5 m/s, the
    crossing of the figure-eight, 22 m/s along the path, Sect. IV).

    Why: trajectories alone hardly identify how the bridle force changes with the wing's shape, since the shape moves
    with the load and seldom alone. Without it the fitted wing's span, held by the power lines' geometric stiffness of
    only ``T / L`` ~ 160 N/m, drifts by decimetres within a second from a force error of 100 N; with the structure's
    1.4 kN/m (and 9-80 kN/m in the stiffer directions) the same error moves it by centimetres. The MLP fits the rest,
    so the model is unchanged on the sampled flights and restores the shape off them."""
    import dataclasses

    from kite_env.dynamics.simulator import FlightSimulator
    from kite_env.frames import kite_frame_rates
    from kite_env.fsi import FlightState
    from kite_env.trajectory import Lemniscate
    from kite_env.wind import WindField

    wind_cfg = dataclasses.replace(cfg.wind, speed_mps=5.0, turbulence_intensity=0.0, gust_speed_mps=0.0)
    sim = FlightSimulator(cfg, WindField(wind_cfg), wing)
    path = Lemniscate(cfg.trajectory)
    sim.reset(path.point(0.0), path.tangent(0.0), 22.0)
    st = sim.state
    o, R, v_k, om = kite_frame_rates(st.r[:4], st.v[:4])
    v_w = np.asarray(sim.wind.velocity(0.0, o[None, :]), float).reshape(3)
    X = FlightState(v_kite=R.T @ v_k, omega=R.T @ om, v_wind=R.T @ v_w)
    sim.wing.solve((st.r[:4] - o) @ R, X, dt=None, support="prescribed", warm=True)
    return np.array(sim.wing.bridle_stiffness(), dtype=float)


# ---------------------------------------------------------------------------------------------------- replay
def tape_config(meta: dict):
    """The config a tape was flown in, with the wind its episode drew (speed, turbulence, realisation)."""
    import dataclasses

    from kite_env.config import load_config

    cfg = load_config(None, meta["overrides"])
    ep = meta["episode"]
    return dataclasses.replace(cfg, wind=dataclasses.replace(cfg.wind, speed_mps=ep["wind_speed_mps"],
                                                             turbulence_intensity=ep["turbulence_intensity"],
                                                             seed=ep["wind_seed"]))


def place_kite(ks, arrays: dict, row: int) -> None:
    """Kite 0 of ``ks`` (:class:`~kite_env.dynamics.fast.SurrogateKites`) at row ``row`` of a tape: the full model's
    positions and velocities made consistent with the fast fidelity's tip constraints (the FE tips flex by
    centimetres), its tether length, reel speed and steering, the latent state at rest."""
    from kite_env.dynamics.kernels import project_constraints

    r0, v0 = project_constraints(arrays["r"][row], arrays["v"][row], ks.m, float(arrays["tether_length"][row]),
                                 ks.tip_lengths, 3, float(arrays["reel_speed"][row]))
    rest = arrays["rest"][row]
    ks.set_kite(0, r0, v0, float(arrays["t"][row]), np.zeros(4), float(rest[1]), float(rest[3]))
    ks.tether_length[0], ks.reel_speed[0] = arrays["tether_length"][row], arrays["reel_speed"][row]
    ks.evaluate()


def replay(arrays: dict, meta: dict, surrogate, start: int = 0, n_steps: int | None = None):
    """The fast fidelity flown along a recorded flight: from row ``start`` of the tape (positions, velocities, tether
    length and reel speed of the full model), with the tape's steering-line rest lengths at every step and the same
    wind. Returns ``(r, v)`` (n, 5, 3) of the fast kites and the status of each step: how far and how soon the
    reduced-order wing drifts from the full model it was fitted to."""
    from kite_env.dynamics.fast import SurrogateKites
    from kite_env.fsi import nominal_wing
    from kite_env.wind import WindField

    cfg = tape_config(meta)
    wind = WindField(cfg.wind)
    q0 = nominal_wing(cfg.kite.name, cfg).design_bridle
    tips = (float(np.linalg.norm(q0[0] - q0[1])), float(np.linalg.norm(q0[2] - q0[3])))
    ks = SurrogateKites(cfg, surrogate, q0, tips, 1, dt=cfg.dynamics.dt_s)  # the tape's step
    ks.set_wind(0, wind)
    rest = arrays["rest"]
    place_kite(ks, arrays, start)
    n = len(arrays["t"]) - 1 - start if n_steps is None else min(n_steps, len(arrays["t"]) - 1 - start)
    r, v, status = np.empty((n + 1, 5, 3)), np.empty((n + 1, 5, 3)), np.zeros(n + 1, dtype=int)
    r[0], v[0] = ks.r[0], ks.v[0]
    for k in range(1, n + 1):
        st = ks.step(np.array([rest[start + k, 1]]), np.array([rest[start + k, 3]]))
        r[k], v[k], status[k] = ks.r[0], ks.v[0], st[0]
    return r, v, status


# ------------------------------------------------------------------------------------------ data as demonstrator
def corrective_samples(arrays: dict, meta: dict, surrogate, cfg, q_design, tips, every: int = 100, horizon: int = 60,
                       omega: float = 20.0):
    """Samples at the states the fitted wing itself reaches along a recorded flight ("data as demonstrator",
    Venkatraman, Hebert & Bagnell, AAAI 2015): from every ``every``-th row the fast fidelity flies ``horizon`` steps
    with the recorded steering and wind; at each of its states the target is the effective force that brings A-D back
    onto the full model's flight, its acceleration there plus a critically damped pull towards its positions and
    velocities (``omega`` [rad/s]). A wing fitted to these restores the shape and the rates it loses in its own
    flight instead of drifting from one error to the next. Returns inputs (n, n_in) and outputs (n, 17)."""
    from kite_env.dynamics.fast import SurrogateKites
    from kite_env.dynamics.particles import ParticleSystem
    from kite_env.wind import WindField

    run_cfg = tape_config(meta)
    wind = WindField(run_cfg.wind)
    ps = ParticleSystem(cfg.dynamics, tips, np.zeros(4), cfg.aero.rho_kg_m3)
    t, r, v, rest = arrays["t"], arrays["r"], arrays["v"], arrays["rest"]
    a = np.full_like(v, np.nan)
    a[1:-1] = (v[2:] - v[:-2]) / (t[2:] - t[:-2])[:, None, None]
    Xs, Ys = [], []
    ks = SurrogateKites(run_cfg, surrogate, q_design, tips, 1, dt=run_cfg.dynamics.dt_s)  # the tape's step
    ks.set_wind(0, wind)
    for s in range(1, len(t) - horizon - 1, every):
        place_kite(ks, arrays, s)
        for k in range(1, horizon + 1):
            j = s + k
            ks.step(np.array([rest[j, 1]]), np.array([rest[j, 3]]))
            rf, vf = ks.r[0], ks.v[0]
            if not (np.all(np.isfinite(rf)) and np.all(np.isfinite(vf))) or np.isnan(a[j]).any():
                break
            ps.set_steering(float(rest[j, 1]), float(rest[j, 3]))
            f, _ = ps.forces(rf, vf, ks.wind[0], np.zeros((4, 3)))
            acc = a[j, :4] + omega * omega * (r[j, :4] - rf[:4]) + 2.0 * omega * (v[j, :4] - vf[:4])
            F_w = ps.m[:4, None] * acc - f[:4]
            y = np.empty(17)
            y[:12] = -(F_w @ ks.R[0]).ravel()
            y[12:15] = np.clip(arrays["alpha"][j], -ALPHA_BOUND, ALPHA_BOUND)
            y[15], y[16] = arrays["lift"][j], arrays["drag"][j]
            Xs.append(ks.X[0].copy())
            Ys.append(y)
            if np.linalg.norm(rf[4] - r[j, 4]) > 5.0:  # far off the flight: the pull no longer describes it
                break
    if not Xs:
        return np.zeros((0, len(surrogate.input_names))), np.zeros((0, 17))
    return np.array(Xs), np.array(Ys)


# ---------------------------------------------------------------------------------------------------- closed loop
def tape_metrics(arrays: dict, cfg, warmup_s: float = 3.0) -> dict:
    """What a flight did, from its tape: how long it flew, its mean tether force and its RMS distance to the
    figure-eight [deg] after ``warmup_s`` (every control step: each fourth row)."""
    from kite_env.trajectory import Lemniscate

    t, r, F = arrays["t"], arrays["r"], arrays["tether_force"]
    path = Lemniscate(cfg.trajectory)
    keep = np.flatnonzero(t - t[0] >= warmup_s)[::4]
    d, s = [], None
    for k in keep:
        n = path.nearest(r[k, 4], s)
        s = n.s
        d.append(n.distance_rad)
    f = F[keep][np.isfinite(F[keep])]
    return {"flown_s": float(t[-1] - t[0]), "traction_mean_N": float(f.mean()) if f.size else float("nan"),
            "tracking_rms_deg": float(np.degrees(np.sqrt(np.mean(np.square(d))))) if d else float("nan")}


def closed_loop(tape_path, surrogate_path) -> tuple[dict, dict, str, str]:
    """The planned episode of a recorded flight flown again in the fast fidelity (same start, wind, turbulence and
    policy, in closed loop): ``(full-model metrics, fast metrics, full-model end, fast end)``
    (:func:`tape_metrics`)."""
    from kite_env.fitting.trajectories import EpisodePlan, fly_plan, load_tape

    arrays, meta = load_tape(tape_path)
    cfg = tape_config(meta)
    plan = EpisodePlan(**meta["plan"])
    fast, fmeta = fly_plan(plan, ["sim.fidelity=surrogate", f"sim.surrogate_path={surrogate_path}"])
    return tape_metrics(arrays, cfg), tape_metrics(fast, cfg), meta["end"], fmeta["end"]
