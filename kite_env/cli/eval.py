"""``kite-eval``: fly a policy in the full aeroelastic model and write metrics, time series and figures.

Example::

    kite-eval --policy baseline --duration 60 --out runs/baseline [--config FILE] [--set section.key=value ...]
              [--seed N] [--force] [--quiet]

writes into ``--out``:

- ``metrics.json``: :func:`kite_env.metrics.compute_metrics` plus ``policy`` and ``wind_seed``,
- ``config.yaml``: the resolved configuration (defaults, file, ``--set``, ``--seed`` and ``--duration`` applied),
- ``timeseries.npz`` / ``timeseries.csv``: :func:`kite_env.metrics.write_timeseries`,
- the figures of :func:`kite_env.plots.make_plots` (``path.png``, ``alpha.png``, ... like the paper's Sect. IV),
- ``command.txt``: the command line.

Everything is written into a temporary sibling folder that is renamed to ``--out`` only when complete, so a failed
or interrupted run (Ctrl-C) leaves nothing half-written. An existing non-empty ``--out`` is refused unless
``--force`` (then it is replaced as a whole at the end).

Exit status: 0 when the files were written, also when the kite crashed (a crash is a result, not an error:
``metrics.json`` has ``crashed: true`` and the ``termination_reason``, and a warning goes to stderr); 2 for bad
input (unknown policy or config key, wrong type, invalid value, missing config file, non-positive duration,
unusable ``--out``), with one line ``kite-eval: error: ...`` on stderr and no output folder; 130 when interrupted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Callable

PROG = "kite-eval"


def _baseline(cfg):
    """The paper's steering and force controller (Sect. III): ``fly`` builds it when given ``policy=None``."""
    return None


#: policy name -> factory(cfg) returning an object with ``reset(s0)`` and ``act(obs) -> dl*`` [m] (see
#: :mod:`kite_env.flight`), or None for the built-in baseline. Register new policies here.
POLICIES: dict[str, Callable] = {"baseline": _baseline}


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error message (no usage dump) and exit status 2."""

    def error(self, message):
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Fly a policy in the full aeroelastic kite model and write metrics, time "
                "series and the paper's Sect. IV figures into --out.",
                epilog="exit status: 0 results written (also when the kite crashed: see metrics.json), "
                "2 bad input (nothing written), 130 interrupted (nothing written)")
    p.add_argument("--policy", default="baseline", help=f"policy to fly (one of: {', '.join(POLICIES)})")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated time [s] (default: sim.duration_s of the config)")
    p.add_argument("--out", required=True, help="output folder (must not exist or be empty, unless --force)")
    p.add_argument("--config", default=None, help="YAML config file (default: built-in defaults)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config value (repeatable)")
    p.add_argument("--seed", type=int, default=None, help="turbulence realisation (sets wind.seed)")
    p.add_argument("--force", action="store_true", help="replace an existing non-empty --out")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    return p


def _fail(msg: str) -> int:
    print(f"{PROG}: error: {msg}", file=sys.stderr)
    return 2


def _fmt(v, spec: str = ".3g") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, (int, float)):
        return format(v, spec)
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x, spec) for x in v) + "]"
    return str(v)


def summary(metrics: dict) -> str:
    """A short table of the main metrics and the paper comparison."""
    rows = [
        ("simulated / wall time [s]", f"{_fmt(metrics['sim_time_s'], '.2f')} / {_fmt(metrics['wall_time_s'], '.1f')}"
                                      f"  (x{_fmt(metrics['real_time_factor'], '.1f')} real time)"),
        ("crashed", f"{_fmt(metrics['crashed'])} ({metrics['termination_reason']})"),
        ("metrics window", metrics["metrics_window"]),
        ("figure-eights completed", _fmt(metrics["figure_eights_completed"])),
        ("figure period [s]", _fmt(metrics["figure_period_s"])),
        ("tracking error RMS [deg]", _fmt(metrics["tracking_error_rms_deg"])),
        ("tether force min/mean/max [N]", " / ".join(_fmt(metrics[f"tether_force_{k}_N"], ".0f")
                                                     for k in ("min", "mean", "max"))),
        ("yaw rate vs steering: r, slope", f"{_fmt(metrics['yaw_rate_steering_corr'])}, "
                                           f"{_fmt(metrics['yaw_rate_steering_slope_deg_s_per_m'])} deg/s per m"),
        ("steering input max [m]", _fmt(metrics["steering_input_max_m"])),
        ("Newton iterations (mean)", _fmt(metrics["newton_iters_mean"])),
    ]
    width = max(len(k) for k, _ in rows)
    lines = [f"  {k:<{width}}  {v}" for k, v in rows]
    comp = metrics.get("paper_comparison", [])
    if comp:
        qw = max(len(r["quantity"]) for r in comp)
        lines.append("")
        lines.append(f"  {'quantity':<{qw}}  {'model':<22}  {'paper':<14}  unit")
        for r in comp:
            lines.append(f"  {r['quantity']:<{qw}}  {_fmt(r['model']):<22}  {_fmt(r['paper']):<14}  {r['unit']}")
    return "\n".join(lines)


def _check_out(out: Path, force: bool) -> str | None:
    """Why ``out`` cannot be written (None if it can)."""
    if out.resolve() == Path.cwd().resolve() or out.resolve().parent == out.resolve():
        return f"--out {str(out)!r} must name a folder other than the current one"
    if out.exists() and not out.is_dir():
        return f"--out {str(out)!r} exists and is not a folder"
    if out.is_dir() and any(out.iterdir()) and not force:
        return f"--out {str(out)!r} exists and is not empty (use --force to replace it)"
    parent = out.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        return f"cannot create --out {str(out)!r}: {str(parent)!r} is not a writable folder"
    return None


def _publish(tmp: Path, out: Path) -> None:
    """Move the finished temporary folder to ``out``, replacing an old ``out`` only at the very end."""
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
        os.replace(out, old / out.name)
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or a parse error (2, message already printed)
        return int(exc.code or 0)
    from kite_env.config import ConfigError, load_config
    from kite_env.geometry import KITES

    if args.policy not in POLICIES:
        return _fail(f"unknown policy {args.policy!r} (valid: {', '.join(POLICIES)})")
    overrides = list(args.overrides)
    if args.duration is not None:
        if not (math.isfinite(args.duration) and args.duration > 0):
            return _fail(f"--duration must be a positive number of seconds, got {args.duration:g}")
        overrides.append(f"sim.duration_s={args.duration!r}")
    if args.seed is not None:
        overrides.append(f"wind.seed={args.seed}")
    if args.config is not None and not Path(args.config).is_file():
        return _fail(f"--config file {args.config!r} does not exist")
    try:
        cfg = load_config(args.config, overrides)
    except ConfigError as exc:
        return _fail(str(exc))
    if cfg.kite.name not in KITES:
        return _fail(f"config key 'kite.name': unknown kite {cfg.kite.name!r} (valid: {', '.join(sorted(KITES))})")
    out = Path(args.out)
    why = _check_out(out, args.force)
    if why:
        return _fail(why)

    from kite_env.flight import fly

    policy = POLICIES[args.policy](cfg)
    duration = cfg.sim.duration_s
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        print(f"{PROG}: policy {args.policy}, {duration:g} s simulated, wind {cfg.wind.speed_mps:g} m/s "
              f"(seed {cfg.wind.seed}), output {out}", flush=True)
        bar = tqdm(total=duration, unit="s", desc="flight", dynamic_ncols=True,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:g} s sim [{elapsed}<{remaining}]")

    def progress(t: float) -> None:
        if bar is not None:
            bar.update(min(t, duration) - bar.n)

    try:
        log = fly(cfg, policy=policy, progress=progress)
        progress(float(log.meta["sim_time_s"]))
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted, nothing written", file=sys.stderr)
        return 130
    finally:
        if bar is not None:
            bar.close()

    from kite_env.metrics import compute_metrics, write_timeseries
    from kite_env.plots import make_plots

    metrics = {"policy": args.policy, "wind_seed": cfg.wind.seed, **compute_metrics(log, cfg)}
    out.resolve().parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.resolve().parent))
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the result folder gets the usual permissions
        import yaml

        with open(tmp / "metrics.json", "w") as fh:
            json.dump(metrics, fh, indent=2, allow_nan=False)
        with open(tmp / "config.yaml", "w") as fh:
            yaml.safe_dump(cfg.to_dict(), fh, sort_keys=False)
        (tmp / "command.txt").write_text(shlex.join([PROG, *argv]) + "\n")
        write_timeseries(log, tmp)
        make_plots(log, cfg, tmp)
        _publish(tmp, out)
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted, nothing written", file=sys.stderr)
        return 130
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    if metrics["crashed"]:
        print(f"{PROG}: warning: the flight ended early at t = {metrics['sim_time_s']:.2f} s "
              f"({metrics['termination_reason']}); results written to {out}", file=sys.stderr)
    if not args.quiet:
        print(summary(metrics))
        print(f"{PROG}: wrote {', '.join(sorted(p.name for p in out.iterdir()))} to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
