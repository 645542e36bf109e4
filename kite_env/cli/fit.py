"""``kite-fit``: make the fast fidelity's reduced-order wing for a model.

    kite-fit sample --out DIR [--episodes N] [--seed S] [--jobs J] [--starts | --agent POLICY] [--config FILE]
                    [--set SECTION.KEY=VALUE ...]
    kite-fit fit --tapes DIR --out FILE.npz [--hidden 128,128] [--epochs 150] [--seed 0] [--config FILE] [--set ...]
    kite-fit slopes --tapes DIR [--every-s 1.0] [--jobs J] [--config FILE] [--set ...]
    kite-fit agreement --out DIR [--surrogate FILE.npz] [--episodes 50] [--jobs J] [--quick]
    kite-fit start-table --out FILE_start.npz [--s-grid 16:58:3] [--w-grid -11:-2:1] [--config FILE] [--set ...]

``sample`` flies the episodes of the sampling plan (:func:`kite_env.fitting.trajectories.sampling_plan`) in the full
model and keeps every physics step of each (``DIR/ep_XXXX.npz``); a run that was stopped goes on where it stopped.
``fit`` fits the reduced-order wing to the tapes (:mod:`kite_env.fitting.fit`; every fifth episode held out) and
writes its weights with the model they belong to, the held-out errors and the command. ``start-table`` tabulates
the full model's start (:mod:`kite_env.surrogate.start`) for the reset of the fast fidelity; it belongs next to the
weights as ``<stem>_start.npz``. Use the result with ``--set sim.surrogate_path=FILE.npz``, or install both into
``kite_env/surrogate/data/<kite>.npz`` and ``<kite>_start.npz``.

``slopes`` solves the static aeroelastic wing at recorded states of the tapes (every ``--every-s`` seconds of each
flight) for its force derivatives there (:mod:`kite_env.fitting.jacobians`), into ``DIR/jacobians/``; ``fit
--slope-weight W`` then fits the wing's slopes to them beside its forces.

``agreement`` flies the paper's controller and random steering in both fidelities and prints the comparison
(:mod:`kite_env.fitting.agreement`); the full model's flights are kept in ``DIR/fe`` for the next comparison.

Exit status: 0 done (``agreement``: and the agreement holds), 1 the agreement does not hold, 2 bad input (one line,
nothing written), 130 interrupted.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
from pathlib import Path


def _sample_worker(args):
    out, n, seed, overrides, start, step, starts, agent, depower = args
    from kite_env.fitting.trajectories import sample_flights

    sample_flights(out, n, seed, overrides, start=start, step=step, log=lambda s: print(s, flush=True),
                   starts=starts, agent=agent, depower=depower)
    return 0


def _overrides(args) -> list[str]:
    """The model's overrides: the config file's values as ``section.key=value`` plus ``--set``."""
    from kite_env.config import load_config

    cfg = load_config(args.config, args.set)  # validates
    base = load_config(None)
    d, d0 = cfg.to_dict(), base.to_dict()
    return [f"{s}.{k}={v}" for s in d for k, v in d[s].items() if v != d0[s][k] and s not in ("env",)]


def _grid(spec: str):
    import numpy as np

    try:
        lo, hi, step = (float(v) for v in spec.split(":"))
    except ValueError:
        raise ValueError(f"a grid is lo:hi:step, got {spec!r}") from None
    return np.round(np.arange(lo, hi + 0.5 * step, step), 10)


def _fit(args) -> int:
    import json
    import shlex

    import numpy as np

    from kite_env.config import fingerprint, load_config
    from kite_env.fitting.fit import (
        FILTERED,
        TAUS,
        FitData,
        build_dataset,
        corrective_samples,
        fit_mlp,
        reference_stiffness,
    )
    from kite_env.fitting.trajectories import load_tape, tape_paths
    from kite_env.fsi import nominal_wing
    from kite_env.surrogate.model import SurrogateWing
    from kite_env.surrogate.samples import git_commit

    hidden = tuple(int(h) for h in args.hidden.split(","))
    cfg = load_config(args.config, args.set)
    if not cfg.structure.dynamic:
        raise ValueError("kite-fit fits the reduced-order wing of the wing with inertia (structure.dynamic: true)")
    if args.out.suffix != ".npz":
        raise ValueError(f"--out must be a .npz file, got '{args.out}'")
    if args.replay_s <= 0 or args.replay_every_s <= 0:
        raise ValueError(f"--replay-s and --replay-every-s must be > 0, got {args.replay_s} and {args.replay_every_s}")
    if args.slope_weight < 0:
        raise ValueError(f"--slope-weight must be >= 0, got {args.slope_weight}")
    slope_names = None
    if args.slope_directions is not None:
        from kite_env.fitting.fit import slope_indices

        slope_names = [n.strip() for n in args.slope_directions.split(",") if n.strip()]
        slope_indices(slope_names)  # one line naming an unknown direction, before anything is read
    wing = nominal_wing(cfg.kite.name, cfg)
    data = build_dataset(args.tapes, cfg, wing, log=lambda m: print(m, flush=True))
    slopes = None
    if args.slope_weight > 0:
        from kite_env.fitting.jacobians import load_jacobians

        slopes = load_jacobians(args.tapes, cfg, {ep["index"] for ep in data.meta["episodes"]})
        if slopes is None:
            raise FileNotFoundError(f"--slope-weight needs the slopes of the tapes: run kite-fit slopes --tapes "
                                    f"{args.tapes}")
    K_b = reference_stiffness(cfg)
    meta = {"model": fingerprint(cfg), "history": {"taus_s": list(TAUS), "filtered": list(FILTERED), "inertial": True},
            "kite": cfg.kite.name, "n_sections": int(len(wing.mesh.sections)), "git_commit": git_commit(),
            "command": shlex.join(["kite-fit", *sys.argv[1:]]), "tapes": data.meta["episodes"]}
    q0 = wing.design_bridle
    tips = (float(np.linalg.norm(q0[0] - q0[1])), float(np.linalg.norm(q0[2] - q0[3])))
    extra_X: list[np.ndarray] = []
    extra_Y: list[np.ndarray] = []
    extra_g: list[np.ndarray] = []
    for rnd in range(args.rounds + 1):
        fit_data = data if not extra_X else FitData(np.vstack([data.inputs, *extra_X]),
                                                     np.vstack([data.outputs, *extra_Y]),
                                                     np.concatenate([data.group, *extra_g]), data.meta)
        W, b, (xm, xs, ym, ys, lo, hi), report = fit_mlp(fit_data, hidden=hidden, epochs=args.epochs,
                                                         batch=args.batch, lr=args.lr, holdout=args.holdout,
                                                         seed=args.seed, K_b=K_b, slopes=slopes,
                                                         slope_weight=args.slope_weight, slope_names=slope_names,
                                                         log=lambda m: print(m, flush=True))
        sw = SurrogateWing(W, b, xm, xs, ym, ys, lo, hi, {**meta, "held_out": report, "rounds": rnd,
                                                          "n_samples": int(len(fit_data.inputs))}, K_b)
        print(f"kite-fit: round {rnd}: bridle-force RMS error {report['force_rms_N']:.1f} N on held-out flights "
              f"({len(fit_data.inputs)} samples)", flush=True)
        if rnd == args.rounds:
            break
        n_new = 0
        dt = cfg.dynamics.dt_s  # the tapes' step
        horizon = max(1, round(args.replay_s / dt))
        for path in tape_paths(args.tapes):
            arrays, tmeta = load_tape(path)
            index = tmeta["plan"]["index"]
            if index % args.holdout == args.holdout - 1:
                continue  # held-out flights stay unseen
            every_s = args.replay_every_s
            if tmeta["plan"]["wind_mps"] < args.dense_below_mps:
                every_s /= 2.0  # low wind: the fast kite's drift grows slowest there and costs it most pull
            Xc, Yc = corrective_samples(arrays, tmeta, sw, cfg, q0, tips, every=max(1, round(every_s / dt)),
                                        horizon=horizon)
            extra_X.append(Xc)
            extra_Y.append(Yc)
            extra_g.append(np.full(len(Xc), index))
            n_new += len(Xc)
        print(f"kite-fit: round {rnd + 1}: {n_new} corrective samples at the fitted wing's own states", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sw.save(args.out)
    print(json.dumps({k: v for k, v in report.items() if k != "rms"}))
    print(f"kite-fit: bridle-force RMS error {report['force_rms_N']:.1f} N = "
          f"{100 * report['force_rms_rel_traction']:.2f} % of the mean traction on held-out flights -> {args.out}")
    return 0


def _slopes_worker(args):
    tapes, overrides, every_s = args
    from kite_env.config import load_config
    from kite_env.fitting.jacobians import compute_jacobians

    return compute_jacobians(tapes, load_config(None, overrides), every_s, log=lambda m: print(m, flush=True))


def _slopes(args, over) -> int:
    if args.every_s <= 0 or args.jobs < 1:
        raise ValueError(f"--every-s must be > 0 and --jobs at least 1, got {args.every_s} and {args.jobs}")
    from kite_env.fitting.trajectories import tape_paths

    tapes = tape_paths(args.tapes)
    if not tapes:
        raise FileNotFoundError(f"no tapes (ep_*.npz) in '{args.tapes}'")
    parts = [tapes[j::args.jobs] for j in range(args.jobs)]
    if args.jobs == 1:
        done = _slopes_worker((parts[0], over, args.every_s))
    else:
        with mp.get_context("spawn").Pool(args.jobs) as pool:
            done = sum(pool.map(_slopes_worker, [(part, over, args.every_s) for part in parts]))
    print(f"kite-fit: slopes of {done} tapes (of {len(tapes)}) -> {Path(args.tapes) / 'jacobians'}")
    return 0


def _start_table(args) -> int:
    from kite_env.config import load_config
    from kite_env.dynamics.start_table import build_start_table

    cfg = load_config(args.config, args.set)
    s, w = _grid(args.s_grid), _grid(args.w_grid)
    table = build_start_table(cfg, s, w, log=lambda m: print(m, flush=True))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table.save(args.out)
    print(f"kite-fit: start table {len(s)} x {len(w)}, {table.meta['n_failed']} points without a converged start "
          f"-> {args.out}")
    return 0


def _agreement(args, base) -> int:
    from kite_env.fitting.agreement import FLIGHTS, Flight, agreement_table, run_agreement

    flights: tuple[Flight, ...] = FLIGHTS
    if args.quick:
        flights = (Flight("5 m/s, 20 s", 5.0, 0.0, 20.0), Flight("8 m/s, turbulence 0.1, 20 s", 8.0, 0.1, 20.0))
        args.episodes, args.duration = min(args.episodes, 4), min(args.duration, 5.0)
    res = run_agreement(args.out, args.surrogate, args.episodes, args.seed, args.duration, flights, args.jobs,
                        base=base, log=lambda m: print(m, flush=True))
    print(agreement_table(res), end="")
    ok = all(r["ok"] for r in res["flights"]) and res["random"]["ok"]
    print(f"kite-fit: agreement {'holds' if ok else 'does not hold'} -> {args.out / 'agreement.md'}")
    return 0 if ok else 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="kite-fit", description="Make the reduced-order wing of a model.")
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("sample", help="fly the sampling plan in the full model, one tape per episode")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--episodes", type=int, default=120)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--jobs", type=int, default=1)
    s.add_argument("--starts", action="store_true", help="short episodes of starts (kite_env.fitting.trajectories."
                   "start_plan) instead of the flights of the sampling plan")
    s.add_argument("--agent", default=None, metavar="POLICY", help="flights of a trained agent (a shipped name or a "
                   "model.zip), alone and with held offsets (kite_env.fitting.trajectories.agent_plan), instead of "
                   "the flights of the sampling plan")
    s.add_argument("--depower", action="store_true", help="flights of the controller with held random offsets on the "
                   "force loop's common line length (kite_env.fitting.trajectories.depower_plan), instead of the "
                   "flights of the sampling plan")
    s.add_argument("--config", default=None, help="physics config (YAML); default: the flying model")
    s.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    f = sub.add_parser("fit", help="fit the reduced-order wing to the tapes")
    f.add_argument("--tapes", required=True, type=Path)
    f.add_argument("--out", required=True, type=Path)
    f.add_argument("--hidden", default="128,128")
    f.add_argument("--epochs", type=int, default=150)
    f.add_argument("--batch", type=int, default=2048)
    f.add_argument("--lr", type=float, default=2e-3)
    f.add_argument("--holdout", type=int, default=5)
    f.add_argument("--seed", type=int, default=0)
    f.add_argument("--rounds", type=int, default=2, help="rounds of corrective samples at the fitted wing's own "
                   "states (data as demonstrator; 0: none)")
    f.add_argument("--replay-s", type=float, default=0.3, help="length of each replay of the corrective samples [s]")
    f.add_argument("--replay-every-s", type=float, default=0.5, help="a replay starts every this many seconds of "
                   "a training flight [s]")
    f.add_argument("--dense-below-mps", type=float, default=0.0, help="flights in wind below this [m/s] get replays "
                   "twice as often (0: none)")
    f.add_argument("--slope-weight", type=float, default=0.0, help="weight of the wing's slopes against the static "
                   "wing's (kite-fit slopes; 0: the forces alone)")
    f.add_argument("--slope-directions", default=None, help="comma-separated names of the slopes to fit (kite_env."
                   "fitting.fit.SLOPE_DIRECTIONS; default: all)")
    f.add_argument("--config", default=None)
    f.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    j = sub.add_parser("slopes", help="the static wing's force derivatives at recorded states, targets of the fit's "
                       "slopes")
    j.add_argument("--tapes", required=True, type=Path)
    j.add_argument("--every-s", type=float, default=1.0, help="one state every this many seconds of flight")
    j.add_argument("--jobs", type=int, default=1)
    j.add_argument("--config", default=None)
    j.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    t = sub.add_parser("start-table", help="tabulate the full model's start for the fast fidelity's reset")
    t.add_argument("--out", required=True, type=Path)
    t.add_argument("--s-grid", default="16:58:3", help="tangential apparent speed lo:hi:step [m/s]")
    t.add_argument("--w-grid", default="-11:-2:1", help="normal apparent velocity lo:hi:step [m/s]")
    t.add_argument("--config", default=None)
    t.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    g = sub.add_parser("agreement", help="fly the baseline and random steering in both fidelities and compare")
    g.add_argument("--out", required=True, type=Path, help="folder of the results (keeps the full model's flights)")
    g.add_argument("--surrogate", default=None, help="weights (.npz) to compare (default: the shipped ones)")
    g.add_argument("--episodes", type=int, default=50)
    g.add_argument("--seed", type=int, default=300)
    g.add_argument("--duration", type=float, default=30.0, help="random-steering episode length [s]")
    g.add_argument("--jobs", type=int, default=1)
    g.add_argument("--quick", action="store_true", help="short flights (20 s, 2 winds, 4 episodes of 5 s): a check "
                   "of the command, not of the agreement")
    g.add_argument("--config", default=None)
    g.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    from kite_env.config import ConfigError

    try:
        over = _overrides(args)
        if args.cmd == "fit":
            return _fit(args)
        if args.cmd == "slopes":
            return _slopes(args, over)
        if args.cmd == "start-table":
            return _start_table(args)
        if args.cmd == "agreement":
            return _agreement(args, over)
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        print(f"kite-fit: error: {exc}", file=sys.stderr)
        return 2
    if args.episodes < 1 or args.jobs < 1:
        print("kite-fit: error: --episodes and --jobs must be at least 1", file=sys.stderr)
        return 2
    if args.starts + (args.agent is not None) + args.depower > 1:
        print("kite-fit: error: --starts, --agent and --depower are three plans; give one", file=sys.stderr)
        return 2
    if args.agent is not None:
        from kite_env.envs.figure_eight import KiteFigureEightEnv
        from kite_env.policies import PolicyError, make_agent

        env = KiteFigureEightEnv(overrides=over)
        try:  # the agent exists and was trained on this model (else one line, nothing flown)
            make_agent(args.agent, env)
        except PolicyError as exc:
            print(f"kite-fit: error: {exc}", file=sys.stderr)
            return 2
        finally:
            env.close()
    try:
        if args.jobs == 1:
            _sample_worker((args.out, args.episodes, args.seed, over, 0, 1, args.starts, args.agent, args.depower))
        else:
            with mp.get_context("spawn").Pool(args.jobs) as pool:
                pool.map(_sample_worker, [(args.out, args.episodes, args.seed, over, j, args.jobs, args.starts,
                                           args.agent, args.depower) for j in range(args.jobs)])
    except KeyboardInterrupt:
        print("kite-fit: interrupted; run the same command again to go on", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
