"""Diagnostic flight experiments with the baseline controller: time-step convergence and a few perturbed flights.

    python analyses/flight_experiments.py branch --at 3.5 --hold 0.8 [--variants hold,mB_x0.5,...] [--set k=v ...]
    python analyses/flight_experiments.py eig --at 3.5 [--steps 4]
    python analyses/flight_experiments.py openloop --dl 0.3 [--duration 4]
    python analyses/flight_experiments.py trim --shorten 0.06 [--duration 8]
    python analyses/flight_experiments.py damp --factor 100 [--duration 25]
    python analyses/flight_experiments.py timestep [--duration 10] [--steps 0.005,0.01,0.0025] [--set k=v ...]

branch    fly the baseline closed loop to --at, then fly deep copies for --hold seconds with the steering held and one
          change each; prints the right tip's alpha peak-to-peak per quarter and how each copy ends.
eig       linearised step map at --at (particle state, central differences over --steps steps with the steering held):
          the leading eigenvalues, their frequency, growth rate and mode shape in frame K.
openloop  steering rest-length difference --dl held from t = 0.5 s, no controller: tip and mid angles of attack.
trim      both steering rest lengths shortened by --shorten after the reset, then the baseline: mu and alpha.
damp      the pair dampers (A-C, B-D, A-D, B-C) multiplied by --factor after the reset, then the baseline.
timestep  the baseline (kite-eval's flight) at each time step of --steps: Newton iterations per step, and against the
          first step the largest distance of the KCU at the common instants and the mean traction after 1 s
          (the time-step check; docs/validation.md, "Time-step convergence"; docs/performance.md, "Newton's
          iterations").

``timestep`` is reported in docs/validation.md, "Time step and Newton tolerance" and "Time-step convergence",
docs/model.md, "Theodorsen's force", and docs/performance.md, "The carried residual"; the other experiments are
diagnostics of the flight's stability (they print what they find; no doc section quotes them now). Not run in CI.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import sys

import numpy as np


def _setup(overrides):
    from kite_env.config import load_config
    from kite_env.control import LineActuator
    from kite_env.dynamics.simulator import FlightSimulator
    from kite_env.policies.baseline import BaselinePolicy
    from kite_env.trajectory import Lemniscate
    from kite_env.wind import WindField

    cfg = load_config(None, overrides)
    path = Lemniscate(cfg.trajectory)
    sim = FlightSimulator(cfg, WindField(cfg.wind))
    pol = BaselinePolicy(cfg.control, path)
    rec = sim.reset(path.point(0.0), path.tangent(0.0))
    pol.reset(0.0)
    return cfg, sim, pol, rec, LineActuator(cfg.control, sim.L_B0, sim.L_D0)


def _fly_to(t_end, overrides):
    """Baseline closed loop up to t_end; returns cfg, simulator and the held rest lengths."""
    cfg, sim, pol, rec, act = _setup(overrides)
    n_ctrl = max(1, int(round(cfg.control.control_dt_s / cfg.dynamics.dt_s)))
    k = 0
    L_B = L_D = sim.L_B0
    while rec.t < t_end - 1e-9:
        if k % n_ctrl == 0:
            dl_star, _ = pol(rec.state.r[4], -rec.R_wk[:, 0], rec.v_kite)  # full-precision state, no env in between
            L_B, L_D, _ = act.rest_lengths(dl_star, rec.line_length, rec.line_tension)
        rec = sim.step(L_B, L_D)
        k += 1
    print(f"at t = {rec.t:.3f} s: L_B - L_D = {L_B - L_D:.3f} m, "
          f"right-tip alpha {math.degrees(rec.wing.alpha[0]):.2f} deg")
    return cfg, sim, L_B, L_D


def _variants():
    def scale_te_mass(f):
        def m(s):
            s.particles.m[[1, 3]] *= f
        return m

    def line_damping(f):
        def m(s):
            c = s.particles.cfg
            s.particles.cfg = dataclasses.replace(c, line_damping_Ns_per_m=c.line_damping_Ns_per_m * f)
        return m

    def pair_damping(f, pairs=(0, 1, 2, 3)):
        def m(s):
            c = s.particles.pair_damping.copy()
            c[list(pairs)] *= f
            s.particles.pair_damping = c
        return m

    def eq3_off(s):
        orig = s.wing.solve
        s.wing.solve = lambda q_b, X, dt=None, **kw: orig(q_b, X, dt=None, **kw)

    def coupling_pc(s):
        s.cfg = dataclasses.replace(s.cfg, dynamics=dataclasses.replace(s.cfg.dynamics, coupling="predictor_corrector"))

    def kb(f):
        def m(s):
            orig = s.wing.bridle_stiffness
            s.wing.bridle_stiffness = lambda: f * orig()
        return m

    return {"hold": lambda s: None, "mB_x0.5": scale_te_mass(0.5), "mB_x2": scale_te_mass(2.0),
            "line_damp_x4": line_damping(4.0), "line_damp_x0": line_damping(0.0), "pair_damp_x100": pair_damping(100.0),
            "pair_AC_x100": pair_damping(100.0, (0,)), "pair_BD_x100": pair_damping(100.0, (1,)),
            "pair_diag_x100": pair_damping(100.0, (2, 3)), "pair_damp_x10": pair_damping(10.0),
            "eq3_off": eq3_off, "pc": coupling_pc, "kb_x0.5": kb(0.5), "kb_x1.5": kb(1.5)}


def branch(args):
    from kite_env.dynamics.simulator import SimulationError

    cfg, sim, L_B, L_D = _fly_to(args.at, args.set)
    snap = copy.deepcopy(sim)  # with the wing's factorisation: every copy continues the same modified Newton
    table = _variants()
    names = list(table) if args.variants == "all" else args.variants.split(",")
    for name in names:
        s = copy.deepcopy(snap)
        table[name](s)
        a, end = [], "ok"
        try:
            for _ in range(int(round(args.hold / cfg.dynamics.dt_s))):
                a.append(math.degrees(s.step(L_B, L_D).wing.alpha[0]))
        except SimulationError:
            end = f"fails at {s.t:.3f} s"
        a = np.asarray(a)
        quarters = np.array_split(a, 4) if a.size >= 8 else [a]
        p2p = " ".join(f"{q.max() - q.min():.1f}" for q in quarters if q.size)
        print(f"{name:16s} {end:18s} right-tip alpha {a.min():6.1f}..{a.max():5.1f} deg, "
              f"peak-to-peak per quarter {p2p}")


def eig(args):
    from kite_env.dynamics.particles import ParticleState
    from kite_env.frames import kite_frame

    cfg, sim, L_B, L_D = _fly_to(args.at, args.set)
    snap = copy.deepcopy(sim)  # with the wing's factorisation: every copy continues the same modified Newton
    y0 = np.concatenate([sim.state.r.ravel(), sim.state.v.ravel()])

    def phi(y):
        s = copy.deepcopy(snap)
        s.state = ParticleState(y[:15].reshape(5, 3).copy(), y[15:].reshape(5, 3).copy())
        s._solve_wing(commit=True)
        for _ in range(args.steps):
            s.step(L_B, L_D)
        return np.concatenate([s.state.r.ravel(), s.state.v.ravel()])

    h = np.r_[np.full(15, 1e-4), np.full(15, 1e-3)]
    J = np.column_stack([(phi(y0 + h[i] * np.eye(30)[i]) - phi(y0 - h[i] * np.eye(30)[i])) / (2 * h[i])
                         for i in range(30)])
    lam, V = np.linalg.eig(J)
    T = args.steps * cfg.dynamics.dt_s
    _, R = kite_frame(*y0[:12].reshape(4, 3))
    for j in np.argsort(-np.abs(lam))[:8]:
        if np.angle(lam[j]) < 0:
            continue
        v = V[:15, j].reshape(5, 3) @ R
        v = v / v.flat[np.argmax(np.abs(v))]
        print(f"|lambda| {abs(lam[j]):.4f}  f {np.angle(lam[j]) / (2 * math.pi * T):.2f} Hz  growth "
              f"{math.log(abs(lam[j])) / T:+.2f} 1/s  |mode| in K (rows A B C D KCU; x y z):")
        print(np.array2string(np.abs(v), precision=2, suppress_small=True))


def openloop(args):
    from kite_env.dynamics.simulator import SimulationError

    cfg, sim, pol, rec, act = _setup(args.set)
    try:
        while rec.t < args.duration - 1e-9:
            d = args.dl if rec.t >= 0.5 else 0.0
            rec = sim.step(sim.L_B0 + 0.5 * d, sim.L_D0 - 0.5 * d)
            if abs(rec.t / 0.25 - round(rec.t / 0.25)) < 1e-6:
                a = np.degrees(rec.wing.alpha)
                print(f"t {rec.t:5.2f}  alpha right {a[0]:5.1f}  mid {a[a.size // 2]:5.1f}  left {a[-1]:5.1f} deg  "
                      f"tensions {np.round(rec.line_tension).astype(int)} N")
    except SimulationError as exc:
        print(f"ends at t = {sim.t:.3f} s: {exc.reason}")


def _fly_modified(args, modify):
    from kite_env import flight
    from kite_env.config import load_config
    from kite_env.dynamics import simulator as S

    orig = S.FlightSimulator.reset

    def reset(self, *a, **k):
        rec = orig(self, *a, **k)
        modify(self)
        return rec

    S.FlightSimulator.reset = reset
    try:
        log = flight.fly(load_config(None, args.set), None, args.duration)
    finally:
        S.FlightSimulator.reset = orig
    se = log.series
    print(f"ends at t = {log.meta['sim_time_s']:.2f} s ({log.meta['termination_reason']})")
    for i in range(0, len(se["t"]), max(1, int(round(0.25 / log.meta["dt_s"])))):
        a = np.degrees(se["alpha"][i])
        print(f"t {se['t'][i]:5.2f}  mu {se['mu'][i]:.3f}  alpha right {a[0]:5.1f}  mid {a[a.size // 2]:5.1f}  "
              f"left {a[-1]:5.1f}  dL {se['steering_input'][i]:.3f} m  path distance "
              f"{math.degrees(se['path_distance'][i]):.1f} deg  elevation {math.degrees(se['elevation'][i]):.0f} deg")


def trim(args):
    def modify(sim):
        sim.L_B0 -= args.shorten
        sim.L_D0 -= args.shorten
        sim.particles.set_steering(sim.L_B0, sim.L_D0)
    _fly_modified(args, modify)


def damp(args):
    def modify(sim):
        sim.particles.pair_damping = sim.particles.pair_damping * args.factor
    _fly_modified(args, modify)


def timestep(args):
    from kite_env import flight
    from kite_env.config import load_config

    try:
        steps = [float(v) for v in args.steps.split(",")]
    except ValueError:
        steps = []
    if len(steps) < 2 or not all(dt > 0 for dt in steps):
        print(f"flight_experiments: error: --steps needs two or more positive time steps [s] (e.g. 0.005,0.01), got "
              f"{args.steps!r}", file=sys.stderr)
        return 2
    if not args.duration > 0:
        print(f"flight_experiments: error: --duration must be positive, got {args.duration}", file=sys.stderr)
        return 2
    series = {}
    for dt in steps:
        cfg = load_config(None, list(args.set) + [f"dynamics.dt_s={dt}"])
        log = flight.fly(cfg, duration_s=args.duration)
        se = log.series
        series[dt] = se
        print(f"dt {1e3 * dt:g} ms: {log.meta.get('termination_reason') or 'completed'}, Newton iterations per step "
              f"{np.mean(se['newton_iters'][1:]):.2f}", flush=True)
    ref = series[steps[0]]
    at = {round(float(t), 6): i for i, t in enumerate(ref["t"])}
    for dt in steps[1:]:
        se = series[dt]
        pairs = [(at[round(float(t), 6)], j) for j, t in enumerate(se["t"]) if round(float(t), 6) in at]
        gap = max(float(np.linalg.norm(ref["r"][i, 4] - se["r"][j, 4])) for i, j in pairs)
        late = [(i, j) for i, j in pairs if ref["t"][i] > 1.0] or pairs  # (after the start, where there is one)
        F0 = np.nanmean([ref["tether_force"][i] for i, _ in late])
        F1 = np.nanmean([se["tether_force"][j] for _, j in late])
        print(f"dt {1e3 * dt:g} ms against {1e3 * steps[0]:g} ms: KCU gap max {100 * gap:.2f} cm, mean traction "
              f"{100 * (F1 / F0 - 1):+.3f} % ({len(pairs)} common instants)")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name, fn in (("branch", branch), ("eig", eig), ("openloop", openloop), ("trim", trim), ("damp", damp),
                     ("timestep", timestep)):
        q = sub.add_parser(name)
        q.set_defaults(fn=fn)
        q.add_argument("--set", action="append", default=[], help="config override section.key=value (repeatable)")
        if name in ("branch", "eig"):
            q.add_argument("--at", type=float, default=3.5, help="time of the snapshot [s]")
        if name == "branch":
            q.add_argument("--hold", type=float, default=0.8, help="seconds flown by each copy")
            q.add_argument("--variants", default="all", help=f"comma list of {', '.join(_variants())} or all")
        if name == "eig":
            q.add_argument("--steps", type=int, default=4, help="steps per map application")
        if name in ("openloop", "trim", "damp"):
            q.add_argument("--duration", type=float, default=4.0 if name == "openloop" else 8.0)
        if name == "openloop":
            q.add_argument("--dl", type=float, default=0.3, help="L_B - L_D held from t = 0.5 s [m]")
        if name == "trim":
            q.add_argument("--shorten", type=float, default=0.06, help="both steering rest lengths shorter by [m]")
        if name == "damp":
            q.add_argument("--factor", type=float, default=100.0, help="pair-damper factor")
        if name == "timestep":
            q.add_argument("--duration", type=float, default=10.0)
            q.add_argument("--steps", default="0.005,0.01,0.0025", help="time steps [s], the first the reference")
    args = p.parse_args(argv)
    bad = [v for v in args.__dict__.get("variants", "all").split(",") if v != "all" and v not in _variants()]
    if bad:
        print(f"flight_experiments: error: unknown variant(s) {bad}; choose from {list(_variants())}", file=sys.stderr)
        return 2
    return args.fn(args) or 0


if __name__ == "__main__":
    sys.exit(main())
