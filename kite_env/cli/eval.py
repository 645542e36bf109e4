"""``kite-eval``: fly policies in the full aeroelastic model and write metrics, time series and figures.

Examples::

    kite-eval --policy baseline --duration 60 --out runs/baseline [--config FILE] [--set section.key=value ...]
              [--seed N] [--episodes N] [--randomize] [--force] [--quiet]
    kite-eval --policy random | constant:0 | runs/ppo/model.zip --episodes 3 --out runs/random
    kite-eval --compare baseline random constant:0 runs/ppo/model.zip --episodes 2 --out runs/compare
    kite-eval end-reasons --episodes 50 --duration 30 --jobs 2 --out runs/end_reasons [--policy random]
              [--seed 0] [--fidelity fe|surrogate] [--config FILE] [--set section.key=value ...]
    kite-eval benchmark --out runs/benchmark [--policies baseline ppo sac random] [--episodes 20] [--seed 1000]
              [--fidelity surrogate fe] [--duration S] [--recipe agents/recipes/ppo.yaml] [--set k=v ...] [--force]

Every policy flies through the Gymnasium environment ``KiteFigureEight-v1`` (:func:`kite_env.flight.run_episode`):
``baseline`` (the paper's controller), ``random``, ``constant:<a>`` (a normalised action in [-1, 1]) or the path
of a model saved by ``kite-train`` (:mod:`kite_env.policies`). By default an episode flies the configured conditions
(the ``wind`` section as it is, start at the crossing of the figure-eight, ``env.randomize = false``); episode ``i``
uses the turbulence realisation ``seed + i`` (``--seed``, default ``wind.seed``) and ``reset(seed=seed + i)``.
``--randomize`` draws wind and start as in training instead (the ``env`` section's ranges).

A run writes into ``--out``:

- ``metrics.json``: :func:`kite_env.metrics.compute_metrics` of the first episode, plus ``policy``, ``wind_seed``,
  ``episode_return`` (first episode), ``episodes`` (count), ``episode_return_mean`` / ``_std`` and
  ``episode_rows`` (one row per episode: return, reward terms, length, end, main metrics),
- ``episodes.csv``: the episode rows,
- ``config.yaml``: the resolved configuration (defaults, file, ``--set``, ``--seed``, ``--duration`` applied),
- ``timeseries.npz`` / ``timeseries.csv`` (first episode): :func:`kite_env.metrics.write_timeseries`,
- the figures of :func:`kite_env.plots.make_plots` (first episode; ``path.png``, ``alpha.png``, ... like the
  paper's Sect. IV),
- ``command.txt``: the command line.

``--compare A B ...`` evaluates each policy (or reads an existing ``kite-eval`` run folder) into ``OUT/<name>/`` and
writes ``OUT/compare.md`` and ``OUT/compare.csv``: the policies side by side (return, crashes, tracking, traction,
figure-eights, L/D, speed), each column the mean +- standard error over its episodes, and for every column after the
first the paired difference of its mean traction from the first column's over the episodes of the same turbulence
seed. Run folders joined by ``+`` (``runs/sac_a+runs/sac_b``) are one column: the episodes of one policy flown in
parts (other seeds, other sessions or machines) pooled, refused unless the parts flew the same policy in the same
configuration (but for the seed) on distinct seeds.

``kite-eval end-reasons`` counts why randomised episodes end (:func:`kite_env.evaluation.end_reasons`): the
episodes of ``kite-eval --randomize`` (by default winds 4-10 m/s, turbulence up to 0.15 and starts anywhere on the
figure-eight, each overridable with ``--set``), each alone in a fresh env, ``--jobs`` processes at a time (episode
``i`` has seed ``seed + i``). It writes ``episodes.csv``, ``end_reasons.md`` (the table, also printed) and, for an
episode that failed numerically, ``failures/seed_N.log`` (the failure's message with the wing solver's residual
history) under ``--out``. A numerical failure of the wing with inertia is counted as "numerical failure" at the time
it happened and makes the exit status 3; a start that does not converge is exit 1 (nothing written), bad input 2.

``kite-eval benchmark`` flies ``--policies`` through ``kite-eval --compare`` with ``--randomize`` in the conditions
of a training recipe (the ``env`` overrides of its ``KiteFigureEightFast-v1`` entry; default the shipped
``agents/recipes/ppo.yaml``), one comparison per ``--fidelity`` into ``OUT/<fidelity>/`` (episode ``i``: seed
``seed + i``, held out), and writes ``OUT/benchmark.md``, rl-baselines3-zoo's table (algo, env_id, mean_reward,
std_reward, n_timesteps, eval_episodes; ``n_timesteps`` the model's training steps) with physical metrics added
(tracking error RMS, mean tether force, crashes, mean flight time), and ``OUT/benchmark.json`` with the same rows
(:mod:`kite_env.evaluation`). A shipped name without its model is left out with a warning.

Everything is written into a temporary sibling folder that is renamed to ``--out`` only when complete, so a failed
or interrupted run (Ctrl-C) leaves nothing half-written. An existing non-empty ``--out`` is refused unless
``--force`` (then it is replaced as a whole at the end).

Exit status: 0 when the files were written, also when the kite crashed (a crash is a result, not an error:
``metrics.json`` has ``crashed: true`` and the ``termination_reason``, and a warning goes to stderr); 2 for bad
input (unknown policy, missing or damaged model file, unknown config key, wrong type, invalid value, missing config
file, non-positive duration or episode count, unusable ``--out``), with one line ``kite-eval: error: ...`` on
stderr and no output folder; 1 when no start converged; 3 when the wing with inertia failed numerically
(:class:`~kite_env.dynamics.simulator.NumericalFailure`: a bug of the simulator, not an end of the flight), with
``kite-eval: error: numerical failure at t = ... (the episode's conditions) ...; nothing written`` and the wing
solver's residual history on stderr and no output folder; 130 when interrupted.
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

import numpy as np

from kite_env.cli import parse_or_status
from kite_env.config import FIDELITIES
from kite_env.evaluation import evaluate_episode, write_rows

PROG = "kite-eval"


#: policies by name; a model file path and ``constant:<value>`` are accepted too (:mod:`kite_env.policies`)
POLICIES = ("baseline", "random", "constant:<value>", "ppo", "sac", "<path to model.zip>")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error message (no usage dump) and exit status 2."""

    def error(self, message):
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Fly a policy in the full aeroelastic kite model and write metrics, time "
                "series and the paper's Sect. IV figures into --out.",
                epilog="exit status: 0 results written (also when the kite crashed: see metrics.json), "
                "1 no start converged, 2 bad input (nothing written), 3 numerical failure of the simulator (a bug; "
                "nothing written), 130 interrupted (nothing written). subcommands: 'kite-eval end-reasons --help' "
                "(why randomised episodes end), 'kite-eval benchmark --help' (rl-zoo table of policies)")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--policy", default="baseline",
                      help="policy to fly: baseline, random, constant:<a> (a in [-1, 1]), ppo / sac (the shipped "
                      "models in agents/models) or a model.zip path")
    what.add_argument("--compare", nargs="+", metavar="POLICY_OR_RUN",
                      help="policies (or existing kite-eval run folders) to evaluate and tabulate side by side")
    p.add_argument("--episodes", type=int, default=1, help="episodes per policy (default 1)")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated time per episode [s] (default: sim.duration_s of the config)")
    p.add_argument("--out", required=True, help="output folder (must not exist or be empty, unless --force)")
    p.add_argument("--config", default=None, help="physics and task config YAML (default: the flying model); every "
                   "policy flies it (an agent trained on another model is refused)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config value (repeatable)")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the first episode: turbulence realisation (wind.seed) and reset seed")
    p.add_argument("--randomize", action="store_true",
                   help="draw wind and start per episode from the env section's ranges (as in training)")
    p.add_argument("--fidelity", choices=FIDELITIES, default=None,
                   help="wing model: fe (the aeroelastic FE wing) or surrogate (the reduced-order wing); default: "
                        "sim.fidelity of the config (fe)")
    p.add_argument("--force", action="store_true", help="replace an existing non-empty --out")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    return p


def _fail(msg: str, prog: str = PROG) -> int:
    print(f"{prog}: error: {msg}", file=sys.stderr)
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
                                      f"  ({_fmt(metrics['real_time_factor'], '.2g')} s of wall time per simulated s)"),
        ("crashed", f"{_fmt(metrics['crashed'])} ({metrics['termination_reason']})"),
        ("metrics window", metrics["metrics_window"]),
        ("figure-eights completed", _fmt(metrics["figure_eights_completed"])),
        ("figure period [s]", _fmt(metrics["figure_period_s"])),
        ("tracking error RMS [deg]", _fmt(metrics["tracking_error_rms_deg"])),
        ("tether force min/mean/max [N]", " / ".join(_fmt(metrics[f"tether_force_{k}_N"], ".0f")
                                                     for k in ("min", "mean", "max"))),
        ("yaw rate vs steering: r, slope", f"{_fmt(metrics['yaw_rate_steering_corr'])}, "
                                           f"{_fmt(metrics['yaw_rate_steering_slope_deg_s_per_m'])} deg/s per m"),
        ("heading rate vs steering: r, slope", f"{_fmt(metrics.get('heading_rate_steering_corr'))}, "
                                               f"{_fmt(metrics.get('heading_rate_steering_slope_deg_s_per_m'))} "
                                               "deg/s per m"),
        ("steering input max [m]", _fmt(metrics["steering_input_max_m"])),
        ("steering line slack (< 50 N), share of time", _fmt(metrics.get("steering_line_slack_fraction"))),
        ("Newton iterations (mean)", _fmt(metrics["newton_iters_mean"])),
        ("steps made in halves", _fmt(metrics.get("substepped_steps"))),
    ]
    if metrics.get("reel_out_speed_mean_mps"):  # dynamics.winch = force
        rows.append(("reel-out: mean speed [m/s], power [kW], tether end [m]",
                     f"{_fmt(metrics['reel_out_speed_mean_mps'])}, "
                     f"{_fmt(metrics['reel_out_power_mean_W'] * 1e-3)}, {_fmt(metrics['tether_length_end_m'], '.1f')}"))
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


class _Job:
    """One policy to evaluate (or an existing run folder to read): its name, spec, config, env and agent."""

    def __init__(self, spec: str, label: str, cfg=None, env=None, agent=None, run_dir: Path | None = None,
                 pooled: dict | None = None):
        self.spec, self.label, self.cfg, self.env, self.agent, self.run_dir = spec, label, cfg, env, agent, run_dir
        self.pooled = pooled  # the metrics of run folders joined by '+' (pool_runs)


def _prepare(spec: str, args, overrides: list[str], label: str) -> _Job:
    """Config, environment and agent for ``spec``; raises ConfigError / PolicyError / ValueError on bad input."""
    from kite_env.config import ConfigError, load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import evaluation_config
    from kite_env.geometry import KITES
    from kite_env.policies import make_agent

    # every policy flies the one env of --config and --set; an agent trained on another model is refused
    # (kite_env.policies.load_model_agent, naming the keys that differ)
    cfg = load_config(args.config, overrides)
    if cfg.kite.name not in KITES:
        raise ConfigError(f"config key 'kite.name': unknown kite {cfg.kite.name!r} (valid: {', '.join(sorted(KITES))})")
    env = KiteFigureEightEnv(config=evaluation_config(cfg, randomize=args.randomize))
    # --seed is applied as wind.seed, so the config's seed is the seed of the first episode
    return _Job(spec, label, env.cfg, env, make_agent(spec, env, seed=cfg.wind.seed))


def _evaluate(job: _Job, args, progress) -> tuple:
    """Fly ``args.episodes`` episodes; returns (log of the first episode, its metrics, episode rows)."""
    seed = job.cfg.wind.seed  # --seed, applied as wind.seed (main)
    first_log, first_metrics, rows = None, None, []
    for i in range(args.episodes):
        options = None if args.randomize else {"wind_seed": seed + i}
        log, m, row = evaluate_episode(job.env, job.agent, seed + i, i, options=options, progress=progress)
        rows.append(row)
        if i == 0:
            first_log, first_metrics = log, m
    job.env.close()
    return first_log, first_metrics, rows


def _episode_stats(rows: list[dict]) -> dict:
    ret = np.array([r["episode_return"] for r in rows], dtype=float)
    return {"episodes": len(rows), "episode_return_mean": float(ret.mean()),
            "episode_return_std": float(ret.std()) if len(rows) > 1 else 0.0}


def _write_run(folder: Path, job: _Job, log, metrics: dict, rows: list[dict], argv: list[str]) -> dict:
    import yaml

    from kite_env.metrics import write_timeseries
    from kite_env.plots import make_plots

    folder.mkdir(parents=True, exist_ok=True)
    out = {"policy": job.spec, "wind_seed": rows[0]["wind_seed"], **metrics,
           "episode_return": rows[0]["episode_return"], **_episode_stats(rows), "episode_rows": rows}
    with open(folder / "metrics.json", "w") as fh:
        json.dump(out, fh, indent=2, allow_nan=False)
    write_rows(folder / "episodes.csv", rows)
    with open(folder / "config.yaml", "w") as fh:
        yaml.safe_dump(job.cfg.to_dict(), fh, sort_keys=False)
    (folder / "command.txt").write_text(shlex.join([PROG, *argv]) + "\n")
    write_timeseries(log, folder)
    make_plots(log, job.cfg, folder)
    return out


#: rows of the comparison table: (label, key of the episode rows, format)
COMPARE_ROWS = (("return", "episode_return", ".4g"), ("flight time [s]", "sim_time_s", ".4g"),
                ("figure-eights", "figure_eights_completed", ".3g"), ("tracking error RMS [deg]",
                                                                      "tracking_error_rms_deg", ".3g"),
                ("tether force mean [N]", "tether_force_mean_N", ".4g"), ("L/D mean", "lift_to_drag_mean", ".3g"),
                ("speed min [m/s]", "kite_speed_min_mps", ".3g"), ("speed max [m/s]", "kite_speed_max_mps", ".3g"))


def mean_se(values) -> tuple[float | None, float | None]:
    """Mean and standard error (sample standard deviation / sqrt(n); 0 for one value) of the finite ``values``."""
    v = np.array([float(x) for x in values if x is not None and np.isfinite(float(x))])
    if v.size == 0:
        return None, None
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0


def env_header(cfg, episodes: int, seed: int, randomize: bool) -> str:
    """One line naming the env every policy of a comparison flew: id, fidelity, model, conditions, seeds."""
    from kite_env.config import fingerprint
    from kite_env.envs import ENV_ID, FAST_ENV_ID

    f = fingerprint(cfg)
    env_id = FAST_ENV_ID if cfg.sim.fidelity == "surrogate" else ENV_ID
    e = cfg.env
    if randomize:
        cond = (f"wind {e.wind_speed_min_mps:g}-{e.wind_speed_max_mps:g} m/s, turbulence "
                f"{e.turbulence_intensity_min:g}-{e.turbulence_intensity_max:g} (drawn per episode)")
    else:
        cond = f"wind {cfg.wind.speed_mps:g} m/s, turbulence {cfg.wind.turbulence_intensity:g}"
    return (f"env {env_id} (fidelity {cfg.sim.fidelity}), model '{f['preset']}' ({f['fingerprint']}), {cond}, "
            f"{episodes} episode(s) of {e.max_episode_s:g} s, seeds {seed}-{seed + episodes - 1}")


def compare_table(results: list[tuple[str, dict]], header: str = "") -> tuple[str, list[dict]]:
    """Markdown table (one column per policy, mean +- standard error over its episodes) under ``header``, and CSV
    rows (one per policy) of the runs ``(name, metrics.json dict)``."""
    csv_rows, cols = [], []
    for name, m in results:
        rows = m.get("episode_rows") or [m]
        col = {"episodes": str(len(rows)),
               "crashed": f"{sum(bool(r['crashed']) for r in rows)}/{len(rows)}",
               "end": "; ".join(sorted({str(r['termination_reason']) for r in rows}))}
        row = {"policy": name, "episodes": len(rows), "crashed": sum(bool(r["crashed"]) for r in rows),
               "end": col["end"]}
        for label, key, spec in COMPARE_ROWS:
            mu, se = mean_se(r.get(key) for r in rows)
            col[label] = "-" if mu is None else (_fmt(mu, spec) + (f" +- {_fmt(se, '.2g')}" if len(rows) > 1 else ""))
            row[f"{key}_mean"], row[f"{key}_se"] = mu, se
        cols.append(col)
        csv_rows.append(row)
    names = [name for name, _ in results]
    paired = f"traction vs {names[0]}, paired by seed [%]" if len(results) > 1 else None
    if paired:
        first = _traction_by_seed(results[0][1])
        for col, row, (_, m) in zip(cols, csv_rows, results):
            mine = _traction_by_seed(m)
            diffs = [100.0 * (mine[k] / first[k] - 1.0) for k in sorted(mine) if k in first and first[k] > 0]
            mu, se = mean_se(diffs)
            col[paired] = "-" if mu is None or m is results[0][1] else (
                f"{mu:+.2f} +- {se:.2g} ({len(diffs)} pairs)" if len(diffs) > 1 else f"{mu:+.2f} (1 pair)")
            row["traction_paired_pct_mean"], row["traction_paired_pct_se"], row["traction_pairs"] = mu, se, len(diffs)
    lines = ([header, ""] if header else []) + ["| | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for label in ["episodes", "crashed", "end", *[r[0] for r in COMPARE_ROWS], *([paired] if paired else [])]:
        lines.append(f"| {label} | " + " | ".join(c[label] for c in cols) + " |")
    return "\n".join(lines) + "\n", csv_rows


def _traction_by_seed(metrics: dict) -> dict:
    """Mean tether force [N] of each episode of a run (also one that ended early), by its turbulence seed."""
    rows = metrics.get("episode_rows") or [metrics]
    return {int(r["wind_seed"]): float(r["tether_force_mean_N"]) for r in rows
            if r.get("wind_seed") is not None and r.get("tether_force_mean_N") is not None}


def pool_runs(folders: list[Path]) -> dict:
    """The ``metrics.json`` of the ``kite-eval`` run folders ``folders`` (one policy flown in parts) as one run: the
    first folder's metrics with the episode rows of all. Raises ValueError (ConfigError for a configuration that no
    longer loads) unless every part flew the same policy in the same configuration but for ``wind.seed`` (each read
    as today's: retired keys at their one value dropped, new keys at their defaults) and no turbulence seed
    repeats."""
    import yaml

    from kite_env.config import config_from_dict, without_retired

    def read(folder: Path) -> tuple[dict, dict]:
        for name in ("metrics.json", "config.yaml"):
            if not (folder / name).is_file():
                raise ValueError(f"--compare: folder {str(folder)!r} has no {name} (not a kite-eval run)")
        # read as today's configuration: a run recorded before keys were retired or added compares by value
        cfg = config_from_dict(without_retired(yaml.safe_load((folder / "config.yaml").read_text()))).to_dict()
        cfg.get("wind", {}).pop("seed", None)
        return json.loads((folder / "metrics.json").read_text()), cfg

    base, cfg0 = read(folders[0])
    rows = list(base.get("episode_rows") or [base])
    for folder in folders[1:]:
        m, cfg = read(folder)
        if m.get("policy") != base.get("policy"):
            raise ValueError(f"--compare: {str(folder)!r} flew policy {m.get('policy')!r}, {str(folders[0])!r} "
                             f"{base.get('policy')!r}: one column pools one policy")
        differ = sorted(f"{sec}.{k}" for sec in set(cfg) | set(cfg0)
                        for k in set(cfg.get(sec) or {}) | set(cfg0.get(sec) or {})
                        if (cfg.get(sec) or {}).get(k) != (cfg0.get(sec) or {}).get(k))
        if differ:
            raise ValueError(f"--compare: {str(folder)!r} and {str(folders[0])!r} flew different configurations "
                             f"({', '.join(differ[:5])}{' ...' if len(differ) > 5 else ''})")
        rows += list(m.get("episode_rows") or [m])
    seeds = [r.get("wind_seed") for r in rows]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--compare: the parts {'+'.join(map(str, folders))} repeat a seed ({sorted(seeds)})")
    return {**base, "episode_rows": rows, **_episode_stats(rows)}


def _labels(specs: list[str]) -> list[str]:
    from kite_env.policies import SHIPPED, policy_label

    out: list[str] = []
    for spec in specs:
        p = Path(spec.split("+")[0])
        pooled = "+" in spec and all(Path(q).is_dir() for q in spec.split("+"))
        base = (p.name + (f"+{spec.count('+')}" if pooled else "") if p.is_dir() and spec not in SHIPPED
                else policy_label(spec))
        label, k = base, 2
        while label in out:
            label, k = f"{base}_{k}", k + 1
        out.append(label)
    return out


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["end-reasons"]:
        return end_reasons(argv[1:])
    if argv[:1] == ["benchmark"]:
        return benchmark(argv[1:])
    args = parse_or_status(build_parser(), argv)
    if isinstance(args, int):
        return args
    overrides = list(args.overrides)
    if args.duration is not None:
        if not (math.isfinite(args.duration) and args.duration > 0):
            return _fail(f"--duration must be a positive number of seconds, got {args.duration:g}")
        overrides.append(f"sim.duration_s={args.duration!r}")
    if args.episodes < 1:
        return _fail(f"--episodes must be at least 1, got {args.episodes}")
    if args.seed is not None:
        overrides.append(f"wind.seed={args.seed}")
    if args.fidelity is not None:
        overrides.append(f"sim.fidelity={args.fidelity}")
    if args.config is not None and not Path(args.config).is_file():
        return _fail(f"--config file {args.config!r} does not exist")
    from kite_env.policies import SHIPPED

    specs = list(args.compare) if args.compare else [args.policy]
    jobs: list[_Job] = []
    try:
        for spec, label in zip(specs, _labels(specs)):
            run = Path(spec)
            parts = [Path(p) for p in spec.split("+")] if args.compare and "+" in spec else []
            if parts and all(p.is_dir() for p in parts):  # one policy's episodes flown in parts, pooled
                jobs.append(_Job(spec, label, run_dir=parts[0], pooled=pool_runs(parts)))
            elif args.compare and run.is_dir() and spec not in SHIPPED:  # the names ppo, sac: the shipped models
                if not (run / "metrics.json").is_file():
                    return _fail(f"--compare: folder {spec!r} has no metrics.json (not a kite-eval run)")
                jobs.append(_Job(spec, label, run_dir=run))
            else:
                jobs.append(_prepare(spec, args, overrides, label))
    except ValueError as exc:  # ConfigError and PolicyError are ValueErrors
        return _fail(str(exc))
    out = Path(args.out)
    why = _check_out(out, args.force)
    if why:
        return _fail(why)

    flying = [j for j in jobs if j.run_dir is None]
    header = ""
    if flying:
        c0 = flying[0].cfg
        header = env_header(c0, args.episodes, c0.wind.seed, args.randomize)
    total = sum(j.cfg.env.max_episode_s for j in flying) * args.episodes
    bar = None
    done = [0.0]
    if not args.quiet and flying:
        from tqdm import tqdm

        j0 = flying[0]
        print(f"{PROG}: {', '.join(j.label for j in flying)}; {args.episodes} episode(s) of "
              f"{j0.cfg.env.max_episode_s:g} s, wind {j0.cfg.wind.speed_mps:g} m/s, output {out}", flush=True)
        bar = tqdm(total=total, unit="s", desc="flight", dynamic_ncols=True,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:g} s sim [{elapsed}<{remaining}]")

    def progress(t: float) -> None:
        if bar is not None:
            bar.update(max(0.0, min(total, done[0] + t) - bar.n))

    from kite_env.dynamics.simulator import NumericalFailure
    from kite_env.envs.figure_eight import StartError

    out.resolve().parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.resolve().parent))
    results: list[tuple[str, dict]] = []
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the result folder gets the usual permissions
        for job in jobs:
            if job.run_dir is not None:
                results.append((job.label, job.pooled or json.loads((job.run_dir / "metrics.json").read_text())))
                continue
            log, metrics, rows = _evaluate(job, args, progress)
            done[0] += job.cfg.env.max_episode_s * args.episodes
            progress(0.0)
            folder = tmp / job.label if args.compare else tmp
            results.append((job.label, _write_run(folder, job, log, metrics, rows, argv)))
        if args.compare:
            md, rows = compare_table(results, header)
            (tmp / "compare.md").write_text(md)
            write_rows(tmp / "compare.csv", rows)
            (tmp / "command.txt").write_text(shlex.join([PROG, *argv]) + "\n")
        if bar is not None:
            bar.close()
            bar = None
        _publish(tmp, out)
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted, nothing written", file=sys.stderr)
        return 130
    except StartError as exc:  # no converged start: one message, nothing written
        if bar is not None:
            bar.close()
            bar = None
        print(f"{PROG}: error: {exc}; nothing written", file=sys.stderr)
        return 1
    except NumericalFailure as exc:  # a bug of the simulator: its message and residual history, nothing written
        if bar is not None:
            bar.close()
            bar = None
        first, _, rest = str(exc).partition("\n")
        print(f"{PROG}: error: {first}; nothing written" + (f"\n{rest}" if rest else ""), file=sys.stderr)
        return 3
    finally:
        if bar is not None:
            bar.close()
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    for name, m in results:
        rows = m.get("episode_rows") or [m]
        for r in rows:
            if r["crashed"]:
                print(f"{PROG}: warning: {name}, episode {r.get('episode', 0)}: the flight ended early at t = "
                      f"{r['sim_time_s']:.2f} s ({r['termination_reason']}); results written to {out}",
                      file=sys.stderr)
    if not args.quiet:
        if args.compare:
            print(compare_table(results, header)[0], end="")
        else:
            m = results[0][1]
            print(summary(m))
            if m["episodes"] > 1:
                print(f"  episodes: {m['episodes']}, return {m['episode_return_mean']:.4g} +- "
                      f"{m['episode_return_std']:.3g}")
        print(f"{PROG}: wrote {', '.join(sorted(p.name for p in out.iterdir()))} to {out}")
    return 0


def build_end_reasons_parser() -> argparse.ArgumentParser:
    from kite_env.evaluation import END_REASON_RANGES

    p = _Parser(prog=f"{PROG} end-reasons", description="Count why randomised episodes end: the episodes of kite-eval "
                "--randomize, each alone in a fresh env, --jobs processes at a time; writes episodes.csv, "
                "end_reasons.md and failures/seed_N.log into --out.",
                epilog=f"conditions before --set: {' '.join(END_REASON_RANGES)}. exit status: 0 counted, 3 counted "
                "with a numerical failure of the simulator (a bug), 1 a start did not converge (nothing written), 2 "
                "bad input (nothing written)")
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--duration", type=float, default=30.0, help="simulated time per episode [s] (default 30)")
    p.add_argument("--jobs", type=int, default=2, help="episodes flown at a time, one process each (default 2)")
    p.add_argument("--policy", default="random", help="as kite-eval --policy (default random)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--out", required=True)
    p.add_argument("--config", default=None, help="physics and task config YAML (default: the flying model)")
    p.add_argument("--fidelity", choices=FIDELITIES, default=None, help="wing model (default: the config's, fe)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    return p


def end_reasons(argv) -> int:
    """``kite-eval end-reasons`` (module docstring): exit status 0, 3 with a numerical failure, 1 when a start did not
    converge, 2 for bad input; nothing written but with 0 or 3."""
    prog = f"{PROG} end-reasons"
    args = parse_or_status(build_end_reasons_parser(), argv)
    if isinstance(args, int):
        return args
    if args.episodes < 1 or args.jobs < 1 or not (math.isfinite(args.duration) and args.duration > 0):
        return _fail("--episodes and --jobs must be >= 1 and --duration > 0", prog)
    if args.config is not None and not Path(args.config).is_file():
        return _fail(f"--config file {args.config!r} does not exist", prog)
    from kite_env.envs.figure_eight import StartError
    from kite_env.evaluation import end_reasons as count, write_end_reasons

    overrides = [*args.overrides, *([f"sim.fidelity={args.fidelity}"] if args.fidelity else [])]
    try:
        result = count(args.episodes, args.seed, args.duration, args.policy, overrides, args.jobs, args.config)
    except StartError as exc:
        print(f"{prog}: error: {exc}; nothing written", file=sys.stderr)
        return 1
    except ValueError as exc:  # ConfigError and PolicyError
        return _fail(str(exc), prog)
    write_end_reasons(result, args.out)
    print(result["table"])
    return 3 if result["failures"] else 0


#: the policies ``kite-eval benchmark`` flies by default
BENCHMARK_POLICIES = ("baseline", "ppo", "sac", "random")


def build_benchmark_parser() -> argparse.ArgumentParser:
    from kite_env.evaluation import BENCHMARK_ENV_IDS
    from kite_env.training import default_recipe

    p = _Parser(prog=f"{PROG} benchmark", description="Benchmark policies against each other on held-out seeds in a "
                "training recipe's randomised conditions: rl-baselines3-zoo's benchmark.md with physical metrics "
                "added.")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--policies", nargs="+", default=list(BENCHMARK_POLICIES),
                   help=f"default: {' '.join(BENCHMARK_POLICIES)}")
    p.add_argument("--episodes", type=int, default=20, help="episodes per policy and fidelity (default 20)")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first episode (default 1000, held out)")
    p.add_argument("--fidelity", nargs="+", choices=tuple(BENCHMARK_ENV_IDS), default=["surrogate"],
                   help="wing models to fly (default: surrogate)")
    p.add_argument("--duration", type=float, default=None, help="episode time limit [s] (default: sim.duration_s)")
    p.add_argument("--recipe", type=Path, default=default_recipe("ppo"),
                   help="training recipe whose KiteFigureEightFast-v1 env overrides set the conditions (default: the "
                   "shipped agents/recipes/ppo.yaml)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="further config overrides (after the recipe's)")
    p.add_argument("--force", action="store_true", help="replace existing kite-eval folders in OUT")
    return p


def benchmark(argv) -> int:
    """``kite-eval benchmark`` (module docstring): exit status 0, or 2 for bad input or a failed kite-eval."""
    from kite_env.evaluation import benchmark_row, benchmark_table, recipe_env

    prog = f"{PROG} benchmark"
    args = parse_or_status(build_benchmark_parser(), argv)
    if isinstance(args, int):
        return args
    from kite_env.policies import SHIPPED, shipped_model
    from kite_env.training import UsageError

    policies, skipped = [], []
    for spec in args.policies:
        if spec in SHIPPED and not shipped_model(spec).is_file():
            print(f"{prog}: warning: policy {spec!r} left out: no shipped model at '{shipped_model(spec)}'",
                  file=sys.stderr)
            skipped.append(spec)
        else:
            policies.append(spec)
    if not policies:
        return _fail("no policy to evaluate", prog)
    try:
        overrides = [*recipe_env(args.recipe), *args.set]
    except (UsageError, ValueError) as exc:
        return _fail(str(exc), prog)
    out = Path(args.out)
    rows = []
    for fidelity in args.fidelity:
        argv = ["--compare", *policies, "--episodes", str(args.episodes), "--seed", str(args.seed), "--randomize",
                "--fidelity", fidelity, "--out", str(out / fidelity), "--quiet"]
        for o in overrides:
            argv += ["--set", o]
        if args.duration is not None:
            argv += ["--duration", repr(float(args.duration))]
        if args.force:
            argv.append("--force")
        if main(argv) != 0:
            return 2  # kite-eval printed the reason
        for spec, label in zip(policies, _labels(policies)):
            metrics = json.loads((out / fidelity / label / "metrics.json").read_text())
            rows.append(benchmark_row(label, spec, fidelity, metrics))
    head = (f"Benchmark of {', '.join(policies)}: {args.episodes} episode(s) per policy and fidelity, "
            f"seeds {args.seed}..{args.seed + args.episodes - 1}, randomised conditions ({', '.join(overrides)}).\n"
            "mean_reward / std_reward: episode return over the episodes; the physical metrics are means over them.\n")
    if skipped:
        head += f"Left out (no shipped model): {', '.join(skipped)}.\n"
    (out / "benchmark.md").write_text(benchmark_table(rows) + "\n" + head)
    info = {"policies": policies, "skipped": skipped, "episodes": args.episodes, "seed": args.seed,
            "fidelity": args.fidelity, "duration_s": args.duration, "overrides": overrides,
            "recipe": str(args.recipe), "rows": rows}
    (out / "benchmark.json").write_text(json.dumps(info, indent=2, allow_nan=False))
    print(benchmark_table(rows), end="")
    print(f"{prog}: wrote {out / 'benchmark.md'} and {out / 'benchmark.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
