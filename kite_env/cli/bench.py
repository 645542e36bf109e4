"""``kite-bench --out DIR``: environment steps per second and real-time factor on one core, per fidelity.

    kite-bench --out DIR [--fidelity fe|surrogate|batched ...] [--steps N] [--fast-steps N] [--n-kites K]
               [--config FILE] [--set section.key=value ...]
    kite-bench wing --out DIR [--kite rhino16] [--steps 100] [--resolutions 21x4,37x6,51x8]
    kite-bench soak --fidelity surrogate|fe|batched --episodes N [--seed 0] [--duration 30] [--jobs 1]
               [--set section.key=value ...] --out DIR
    kite-bench soak --merge DIR [DIR ...] --out DIR
    kite-bench warm [--fidelity fe|surrogate|batched ...]

Prints a table and writes ``DIR/bench.json`` as ``{"fe": {"env_steps_per_s": ..., "real_time_factor": ...},
"surrogate": {...}, "batched": {"n_kites": 64, "kite_steps_per_s": ...}}`` (``fe``: the aeroelastic FE wing;
``surrogate``: the reduced-order wing, ``KiteFigureEightFast-v1``; ``batched``: the vector env of the surrogate
fidelity, all kites in one process)
(real-time factor = wall seconds per simulated second, as ``kite-eval``; below 1 is faster than real time). The env
is reset (timed separately) and then stepped with the paper's controller, so that the flight is the one users see;
an episode that ends early is reset and the count goes on (:func:`kite_env.benchmark.bench_env`). Another time step
of the full model: ``--set dynamics.dt_s=0.01``.

``kite-bench wing`` times the static aeroelastic wing alone (one cold solve, warm steps of a steering manoeuvre at
the paper's 5.3 ms step) at several mesh resolutions, prints a table and writes ``DIR/bench_wing.json``
(:func:`kite_env.benchmark.bench_wing`).

``kite-bench soak`` flies random actions in the training conditions and checks every step for finite values
(:mod:`kite_env.soak`), writes ``DIR/soak.json`` and ``DIR/soak.md`` and prints the table; ``--merge`` joins soaks
flown in parts over disjoint seeds into one. Exit status 0 when no step was non-finite and nothing raised, 1
otherwise, 2 for bad input (nothing written).

``kite-bench warm`` compiles the numba kernels of each fidelity into numba's on-disk cache by a short flight
(:func:`kite_env.benchmark.warm_kernels`), so that the processes after it load them instead of compiling; the test
command runs it before its workers start.
"""

from __future__ import annotations

import argparse
import sys

from kite_env.benchmark import bench_batched, bench_env
from kite_env.cli import parse_or_status
from kite_env.config import ConfigError


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["soak"]:
        return soak(argv[1:])
    if argv[:1] == ["wing"]:
        return wing(argv[1:])
    if argv[:1] == ["warm"]:
        return warm(argv[1:])
    p = argparse.ArgumentParser(prog="kite-bench", description=__doc__.split("\n\n")[0],
                                epilog="subcommands: 'kite-bench wing --help' (the static wing), 'kite-bench soak "
                                "--help' (random-action episodes, every step checked), 'kite-bench warm --help' "
                                "(compile the kernels into the cache)")
    p.add_argument("--out", required=True, help="folder for bench.json")
    p.add_argument("--steps", type=int, default=150, help="env steps of the fe fidelity (default 150 = 3 s of flight)")
    p.add_argument("--fast-steps", type=int, default=3000,
                   help="env steps of the surrogate fidelity, single and batched (default 3000)")
    p.add_argument("--n-kites", type=int, default=64, help="kites of the batched env (default 64)")
    p.add_argument("--fidelity", action="append", choices=("fe", "surrogate", "batched"), default=None,
                   help="benchmark only these (repeatable; default all)")
    p.add_argument("--config", default=None, help="physics and task config YAML (default: the flying model; the fast "
                   "fidelity needs a reduced-order wing fitted to it); --set overrides apply on top")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    if args.steps <= 0:
        print(f"kite-bench: error: --steps must be positive, got {args.steps}", file=sys.stderr)
        return 2
    from kite_env.benchmark import pin_to_one_core, write_json

    pin_to_one_core()
    which = args.fidelity or ["fe", "surrogate", "batched"]
    result = {}
    try:
        if "fe" in which:
            result["fe"] = bench_env(args.steps, args.set, config=args.config)
        if "surrogate" in which:
            result["surrogate"] = bench_env(args.fast_steps, args.set, fidelity="surrogate", config=args.config)
        if "batched" in which:
            result["batched"] = bench_batched(args.n_kites, args.fast_steps, args.set, config=args.config)
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        print(f"kite-bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"{'fidelity':<10} {'env steps/s':>12} {'real-time factor':>17} {'reset [s]':>10}")
    for name, r in result.items():
        if name == "batched":
            print(f"{name:<10} {r['kite_steps_per_s']:>12.1f} {r['real_time_factor']:>17.4f} {'-':>10}"
                  f"  ({r['n_kites']} kites: kite-steps/s, wall per simulated second of all kites)")
        else:
            newton = (f"  Newton iterations per step {r['newton_iters_mean']:.2f} (p99 {r['newton_iters_p99']:.0f}, "
                      f"max {r['newton_iters_max']})" if "newton_iters_mean" in r else "")
            print(f"{name:<10} {r['env_steps_per_s']:>12.1f} {r['real_time_factor']:>17.4f} {r['reset_s']:>10.2f}"
                  + newton)
    write_json(args.out, "bench.json", result)
    print(f"kite-bench: wrote {args.out}/bench.json")
    return 0


def warm(argv) -> int:
    """``kite-bench warm``: compile the kernels of each fidelity into numba's cache (module docstring)."""
    from kite_env.benchmark import warm_kernels

    p = argparse.ArgumentParser(prog="kite-bench warm", description="Compile the numba kernels of each fidelity into "
                                "numba's on-disk cache by a short flight, so that later processes load them.")
    p.add_argument("--fidelity", action="append", choices=("fe", "surrogate", "batched"), default=None,
                   help="warm only these (repeatable; default all)")
    args = parse_or_status(p, argv)
    if isinstance(args, int):
        return args
    for fidelity in args.fidelity or ["fe", "surrogate", "batched"]:
        print(f"kite-bench warm: {fidelity} {warm_kernels(fidelity):.1f} s", flush=True)
    return 0


def wing(argv) -> int:
    """``kite-bench wing``: the static aeroelastic wing on one core (module docstring)."""
    from kite_env.benchmark import WING_RESOLUTIONS

    default = ",".join(f"{ns}x{nc}" for ns, nc in WING_RESOLUTIONS)
    p = argparse.ArgumentParser(prog="kite-bench wing", description="Benchmark of the static aeroelastic wing on one "
                                "core: a cold solve and warm steps per mesh resolution; prints a table and writes "
                                "DIR/bench_wing.json.")
    p.add_argument("--out", required=True, help="output folder for bench_wing.json")
    p.add_argument("--kite", default="rhino16")
    p.add_argument("--steps", type=int, default=100, help="warm steps per resolution (default 100)")
    p.add_argument("--resolutions", default=default,
                   help=f"comma-separated SECTIONSxCHORD list (default {default}); the table's summary row is 37x6")
    args = parse_or_status(p, argv)
    if isinstance(args, int):
        return args
    try:
        res = [tuple(int(v) for v in r.split("x")) for r in args.resolutions.split(",")]
        if any(len(r) != 2 for r in res):
            raise ValueError
    except ValueError:
        print(f"kite-bench wing: error: --resolutions must look like {default}, got {args.resolutions!r}",
              file=sys.stderr)
        return 2
    if args.steps < 1:
        print("kite-bench wing: error: --steps must be >= 1", file=sys.stderr)
        return 2
    from pathlib import Path

    from kite_env.benchmark import PAPER_WALL_PER_STEP_MS, bench_wing, format_table, pin_to_one_core, write_json
    from kite_env.geometry import KITES

    if args.kite not in KITES:
        print(f"kite-bench wing: error: unknown kite {args.kite!r} (valid: {', '.join(sorted(KITES))})",
              file=sys.stderr)
        return 2
    pin_to_one_core()
    result = bench_wing(args.kite, res, args.steps,
                        progress=lambda kite, ns, nc: print(f"kite-bench wing: {kite} {ns}x{nc} ...", flush=True))
    write_json(args.out, "bench_wing.json", result)
    print(format_table(result["resolutions"]))
    print(f"paper (Matlab, RK45 mean step 5.3 ms): {PAPER_WALL_PER_STEP_MS:.0f} ms wall per step; "
          f"target: warm step < 5 ms at 37x6")
    print(f"kite-bench wing: wrote {Path(args.out) / 'bench_wing.json'}")
    return 0


def soak(argv) -> int:
    """``kite-bench soak``: random-action episodes, every step checked (module docstring, :mod:`kite_env.soak`)."""
    p = argparse.ArgumentParser(prog="kite-bench soak", description="Soak an environment with random actions (every "
                                "observation and reward checked for finite values, every exception counted) and "
                                "print the table; writes DIR/soak.json and DIR/soak.md.",
                                epilog="exit status: 0 no non-finite step and no exception, 1 otherwise, 2 bad input "
                                "(nothing written)")
    p.add_argument("--fidelity", choices=("surrogate", "fe", "batched"),
                   help="surrogate / fe: the single env of that wing; batched: the fast fidelity's vector env")
    p.add_argument("--episodes", type=int)
    p.add_argument("--merge", nargs="+", metavar="DIR", help="merge these soaks (disjoint seeds) into one table")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--out", required=True)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = parse_or_status(p, argv)
    if isinstance(args, int):
        return args
    if args.merge:
        return _merge(args.merge, args.out)

    def fail(msg: str) -> int:
        print(f"kite-bench soak: error: {msg}", file=sys.stderr)
        return 2

    if args.fidelity is None or args.episodes is None:
        return fail("--fidelity and --episodes are required (or --merge DIR ...)")
    if args.episodes < 1 or args.jobs < 1 or args.duration <= 0:
        return fail("--episodes and --jobs must be >= 1 and --duration > 0")
    from kite_env.config import load_config
    from kite_env.soak import soak as fly_soak

    try:
        load_config(None, args.set)
    except ConfigError as exc:
        return fail(str(exc))
    return _report(fly_soak(args.fidelity, args.episodes, args.seed, args.duration, args.jobs, args.set), args.out)


def _report(result: dict, out) -> int:
    """Write a soak's result to ``out``, print its table and the first exceptions; exit status 0 when no step was
    non-finite and nothing raised, else 1."""
    from kite_env.soak import soak_table, write

    write(result, out)
    print(soak_table(result), end="")
    for row in result["exceptions"][:5]:
        print(f"seed {row['seed']}: {row['exception']}", file=sys.stderr)
    return 0 if not result["exceptions"] and not result["non_finite_steps"] else 1


def _merge(dirs, out) -> int:
    import json
    from pathlib import Path

    from kite_env.soak import merge

    parts = []
    for d in dirs:
        f = Path(d) / "soak.json"
        if not f.is_file():
            print(f"kite-bench soak: error: {f} does not exist (not a soak folder)", file=sys.stderr)
            return 2
        parts.append(json.loads(f.read_text()))
    try:
        result = merge(parts)
    except ValueError as exc:
        print(f"kite-bench soak: error: {exc}", file=sys.stderr)
        return 2
    return _report(result, out)


#: the command's own names, and the benchmarks it hands on (kite_env.benchmark)
__all__ = ["bench_batched", "bench_env", "main", "soak", "wing"]


if __name__ == "__main__":
    sys.exit(main())
