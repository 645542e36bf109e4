"""Benchmark the trained agents against the baseline and random actions on held-out seeds.

    python scripts/benchmark_agents.py --out runs/benchmark [--policies baseline ppo sac random] [--episodes 20]
        [--seed 1000] [--fidelity surrogate fe] [--duration S] [--recipe agents/recipes/ppo.yaml] [--set k=v ...]
        [--force] [--learning-curves RUN_DIR [RUN_DIR ...]]

Every policy flies ``--episodes`` episodes through ``kite-eval --compare`` (its policies: ``baseline``, ``random``,
``ppo`` / ``sac`` for the shipped models of ``agents/models``, a ``model.zip`` path) with ``--randomize`` and the
``env`` overrides of the training recipe (the ``KiteFigureEightFast-v1`` entry of ``--recipe``), so each episode
draws wind, turbulence and start from the training ranges; episode ``i`` uses ``reset(seed=seed + i)`` (held out:
training and its evaluations use other seeds). One ``kite-eval`` comparison per fidelity goes into
``OUT/<fidelity>/``. A shipped name without its model is left out with a warning.

Writes ``OUT/benchmark.md``: a table in rl-baselines3-zoo's ``benchmark.md`` format (algo, env_id, mean_reward,
std_reward, n_timesteps, eval_episodes; ``n_timesteps`` = training steps of the model, ``-`` for baseline and
random) with physical metrics added (tracking error RMS, mean tether force, crashes, mean flight time; means over
the episodes), one row per (policy, fidelity), and ``OUT/benchmark.json`` with the same rows.

``--learning-curves RUN_DIR ...`` plots the evaluation returns against training steps (``RUN_DIR/eval/
evaluations.npz``) and the training episode returns (``RUN_DIR/monitor.csv``, moving average) of each kite-train
run into ``OUT/learning_curves.png``. Given without ``--policies``, only the curves are made.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import zipfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_POLICIES = ("baseline", "ppo", "sac", "random")
DEFAULT_RECIPE = ROOT / "agents" / "recipes" / "ppo.yaml"
#: env id of each fidelity (the hyperparameter keys of kite-train)
ENV_IDS = {"surrogate": "KiteFigureEightFast-v1", "fe": "KiteFigureEight-v1"}
#: rl-baselines3-zoo's benchmark columns, then the physical metrics: (header, key of the row)
COLUMNS = [("algo", "algo"), ("env_id", "env_id"), ("mean_reward", "mean_reward"), ("std_reward", "std_reward"),
           ("n_timesteps", "n_timesteps"), ("eval_episodes", "eval_episodes"),
           ("tracking error RMS [deg]", "tracking_error_rms_deg"), ("mean tether force [N]", "tether_force_mean_N"),
           ("crashes (n/N)", "crashes"), ("mean flight time [s]", "flight_time_mean_s")]


def training_steps(model: Path) -> int | None:
    """Training steps of a saved SB3 model: ``num_timesteps`` of its zip, else ``timesteps`` of the run's
    ``args.yml`` next to it; None when neither is readable."""
    try:
        with zipfile.ZipFile(model) as zf:
            n = json.loads(zf.read("data").decode()).get("num_timesteps")
        if n is not None:
            return int(n)
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        pass
    args = model.with_name("args.yml")
    if args.is_file():
        n = (yaml.safe_load(args.read_text()) or {}).get("timesteps")
        return None if n is None else int(n)
    return None


def _mean(rows: list[dict], key: str) -> float | None:
    vals = [float(r[key]) for r in rows if r.get(key) is not None and math.isfinite(float(r[key]))]
    return float(np.mean(vals)) if vals else None


def benchmark_row(label: str, spec: str, fidelity: str, metrics: dict) -> dict:
    """One row of the benchmark from a kite-eval run's ``metrics.json`` dict."""
    from kite_env.policies import model_path

    rows = metrics.get("episode_rows") or [metrics]
    model = model_path(spec)
    steps = training_steps(model) if model is not None and model.is_file() else None
    return {"algo": label, "policy": spec, "fidelity": fidelity, "env_id": ENV_IDS[fidelity],
            "mean_reward": float(metrics["episode_return_mean"]), "std_reward": float(metrics["episode_return_std"]),
            "n_timesteps": steps, "eval_episodes": len(rows),
            "tracking_error_rms_deg": _mean(rows, "tracking_error_rms_deg"),
            "tether_force_mean_N": _mean(rows, "tether_force_mean_N"),
            "crashes": f"{sum(bool(r['crashed']) for r in rows)}/{len(rows)}",
            "flight_time_mean_s": _mean(rows, "sim_time_s")}


def _cell(v, key: str) -> str:
    if v is None:
        return "-"
    if key in ("mean_reward", "std_reward"):
        return f"{v:.2f}"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def benchmark_table(rows: list[dict]) -> str:
    """The rows as a Markdown table (rl-zoo's columns first)."""
    heads = [h for h, _ in COLUMNS]
    align = ["---" if k in ("algo", "env_id", "n_timesteps", "crashes") else "---:" for _, k in COLUMNS]
    lines = ["| " + " | ".join(heads) + " |", "|" + "|".join(align) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r[k], k) for _, k in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def run_benchmark(policies: list[str], fidelity: str, out: Path, episodes: int, seed: int, overrides: list[str],
                  duration: float | None, force: bool) -> list[dict] | None:
    """``kite-eval --compare`` of ``policies`` into ``out``; the benchmark rows, or None when kite-eval failed."""
    from kite_env.cli import eval as eval_cli

    argv = ["--compare", *policies, "--episodes", str(episodes), "--seed", str(seed), "--randomize",
            "--fidelity", fidelity, "--out", str(out), "--quiet"]
    for o in overrides:
        argv += ["--set", o]
    if duration is not None:
        argv += ["--duration", repr(float(duration))]
    if force:
        argv.append("--force")
    if eval_cli.main(argv) != 0:
        return None
    rows = []
    for spec, label in zip(policies, eval_cli._labels(policies)):
        metrics = json.loads((out / label / "metrics.json").read_text())
        rows.append(benchmark_row(label, spec, fidelity, metrics))
    return rows


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    n = max(1, min(n, x.size))
    return np.convolve(x, np.ones(n) / n, mode="valid")


def read_monitor(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Episode returns of a (Vec)Monitor file and the training steps at which each episode ended (cumulative
    episode lengths over all envs)."""
    data = np.genfromtxt(path, delimiter=",", skip_header=2, usecols=(0, 1), ndmin=2)
    if data.size == 0:
        return np.zeros(0), np.zeros(0)
    return data[:, 0], np.cumsum(data[:, 1])


def plot_learning_curves(runs: list[Path], out_png: Path) -> list[str]:
    """Evaluation returns vs training steps (mean and std over the evaluation episodes), smoothed training
    episode returns, and, where ``scripts/select_checkpoint.py`` was run, the checkpoints' validation returns with
    the baseline's on the same episodes (``RUN_DIR/selection.json``) of each run; returns the runs that had none of
    these files (warnings)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_e, ax_t, ax_v) = plt.subplots(1, 3, figsize=(16, 4), constrained_layout=True)
    missing = []
    for k, run in enumerate(runs):
        color = f"C{k % 10}"
        found = False
        ev = run / "eval" / "evaluations.npz"
        if ev.is_file():
            d = np.load(ev)
            steps, res = d["timesteps"], np.asarray(d["results"], dtype=float).reshape(len(d["timesteps"]), -1)
            mean, std = res.mean(axis=1), res.std(axis=1)
            ax_e.plot(steps, mean, "o-", color=color, label=run.name)
            ax_e.fill_between(steps, mean - std, mean + std, color=color, alpha=0.2)
            found = True
        mon = run / "monitor.csv"
        if mon.is_file():
            ret, steps = read_monitor(mon)
            if ret.size:
                n = max(1, ret.size // 20)
                ax_t.plot(steps, ret, ".", color=color, alpha=0.15, ms=2)
                ax_t.plot(steps[n - 1:], _moving_average(ret, n), color=color, label=f"{run.name} (mean of {n})")
            found = True
        sel = run / "selection.json"
        if sel.is_file():
            d = json.loads(sel.read_text())
            rows = [r for r in d["rows"] if r.get("steps") is not None]
            base = [r for r in d["rows"] if r.get("checkpoint") == "baseline"]
            lo, hi = d["validation_seeds"]
            ax_v.plot([r["steps"] for r in rows], [r["mean_return"] for r in rows], "o-", color=color,
                      label=f"{run.name} (seeds {lo}-{hi}); best {d['best_steps']:,}")
            if base:
                ax_v.axhline(base[0]["mean_return"], color=color, ls="--", lw=1,
                             label=f"baseline on {run.name}'s seeds")
            found = True
        if not found:
            missing.append(str(run))
    ax_e.set(xlabel="training steps", ylabel="episode return", title="evaluation (held-out seeds, deterministic)")
    ax_t.set(xlabel="training steps (cumulative episode lengths)", ylabel="episode return",
             title="training episodes (monitor.csv)")
    ax_v.set(xlabel="training steps", ylabel="mean episode return",
             title="checkpoint validation (select_checkpoint.py)")
    for ax in (ax_e, ax_t, ax_v):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=120)
    plt.close(fig)
    return missing


def recipe_env(recipe: Path) -> list[str]:
    """The ``env`` overrides of the recipe's ``KiteFigureEightFast-v1`` entry as ``--set`` strings."""
    from kite_env.training import FAST_ENV_ID, load_hyperparameters, recipe_overrides

    algo = "sac" if recipe.stem == "sac" else "ppo"  # only the env entry is used
    # the training-only start rule table_only becomes table in every evaluation (flight.evaluation_config)
    return recipe_overrides(load_hyperparameters(recipe, algo, FAST_ENV_ID))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--policies", nargs="+", default=None, help=f"default: {' '.join(DEFAULT_POLICIES)}")
    p.add_argument("--episodes", type=int, default=20, help="episodes per policy and fidelity (default 20)")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first episode (default 1000, held out)")
    p.add_argument("--fidelity", nargs="+", choices=tuple(ENV_IDS), default=["surrogate"],
                   help="wing models to fly (default: surrogate)")
    p.add_argument("--duration", type=float, default=None, help="episode time limit [s] (default: sim.duration_s)")
    p.add_argument("--recipe", type=Path, default=DEFAULT_RECIPE,
                   help="hyperparameter YAML whose KiteFigureEightFast-v1 env overrides set the conditions")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="further config overrides (after the recipe's)")
    p.add_argument("--force", action="store_true", help="replace existing kite-eval folders in OUT")
    p.add_argument("--learning-curves", nargs="+", type=Path, default=None, metavar="RUN_DIR",
                   help="kite-train run folders to plot into OUT/learning_curves.png")
    args = p.parse_args(argv)
    from kite_env.config import ConfigError
    from kite_env.policies import SHIPPED, shipped_model
    from kite_env.training import UsageError

    out = args.out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.learning_curves:
        for run in plot_learning_curves(args.learning_curves, out / "learning_curves.png"):
            print(f"benchmark_agents: warning: {run}: no eval/evaluations.npz and no monitor.csv", file=sys.stderr)
        print(f"benchmark_agents: wrote {out / 'learning_curves.png'}")
        if args.policies is None:
            return 0
    policies, skipped = [], []
    for spec in args.policies or DEFAULT_POLICIES:
        if spec in SHIPPED and not shipped_model(spec).is_file():
            print(f"benchmark_agents: warning: policy {spec!r} left out: no shipped model at "
                  f"'{shipped_model(spec)}'", file=sys.stderr)
            skipped.append(spec)
        else:
            policies.append(spec)
    if not policies:
        print("benchmark_agents: error: no policy to evaluate", file=sys.stderr)
        return 2
    try:
        overrides = [*recipe_env(args.recipe), *args.set]
    except (UsageError, ConfigError) as exc:
        print(f"benchmark_agents: error: {exc}", file=sys.stderr)
        return 2
    rows = []
    for fidelity in args.fidelity:
        got = run_benchmark(policies, fidelity, out / fidelity, args.episodes, args.seed, overrides, args.duration,
                            args.force)
        if got is None:
            return 2  # kite-eval printed the reason
        rows += got
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
    print(f"benchmark_agents: wrote {out / 'benchmark.md'} and {out / 'benchmark.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
