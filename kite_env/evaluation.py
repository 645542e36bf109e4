"""Evaluation over many episodes: ``kite-eval``'s episode rows, the count of why episodes end (``kite-eval
end-reasons``) and the rl-baselines3-zoo style benchmark table of policies (``kite-eval benchmark``).

:func:`evaluate_episode` flies one episode (:func:`kite_env.flight.run_episode`) and gives ``kite-eval``'s row of it:
the episode's draws, return, reward terms and length with the main metrics (:data:`EPISODE_METRICS`).

:func:`end_reasons` flies many randomised episodes, one per seed and each alone in a fresh environment (episode ``i``
with seed ``seed + i``, as ``kite-eval --randomize --seed`` flies it), ``jobs`` processes at a time, and counts how
they end (:func:`end_reasons_table`). By default winds are drawn from 4-10 m/s, turbulence up to 0.15 and starts
anywhere on the figure-eight (:data:`END_REASON_RANGES`, each overridable). With the wing with inertia (the default)
a numerical failure is not an end of the episode but an error of the simulator (``NumericalFailure``): it is counted
as "numerical failure" at the time it happened, with its message kept. With the paper's quasi-static wing
(``structure.dynamic=false``) the episode ends instead ("wing did not converge", "non-finite ..."): numerical too.
Ground contact and (on the paper's rod tether) a slack tether are physical ends. A drawn start whose wing does not
converge is drawn again by the env; the table's last line counts those failed starts.

:func:`benchmark_row` and :func:`benchmark_table` turn ``kite-eval --compare`` runs into rl-baselines3-zoo's
``benchmark.md`` (algo, env_id, mean_reward, std_reward, n_timesteps, eval_episodes) with physical metrics added.
"""

from __future__ import annotations

import csv
import json
import math
import zipfile
from collections import Counter
from pathlib import Path

import numpy as np

#: per-episode columns of ``episodes.csv`` / ``episode_rows`` taken from the episode's metrics
EPISODE_METRICS = ("sim_time_s", "crashed", "termination_reason", "figure_eights_completed", "tracking_error_rms_deg",
                   "tether_force_mean_N", "tether_force_max_N", "kite_speed_min_mps", "kite_speed_max_mps",
                   "lift_to_drag_mean", "alpha_mid_mean_deg", "real_time_factor", "substepped_steps")


def evaluate_episode(env, agent, seed: int, episode: int = 0, options: dict | None = None, progress=None) -> tuple:
    """Fly one episode of ``env`` with ``agent`` from ``reset(seed=seed)``; returns ``(log, metrics, row)``: the
    flight log, :func:`kite_env.metrics.compute_metrics` of it and ``kite-eval``'s episode row (``episode``,
    ``seed``, the episode's draws, return, reward terms and length, and :data:`EPISODE_METRICS`)."""
    from kite_env.flight import run_episode
    from kite_env.metrics import compute_metrics

    log, info = run_episode(env, agent, seed=seed, options=options, progress=progress)
    m = compute_metrics(log, env.cfg)
    return log, m, {"episode": episode, "seed": seed, **info, **{k: m[k] for k in EPISODE_METRICS}}


def write_rows(path: str | Path, rows: list[dict]) -> None:
    """``rows`` as a CSV file, the columns in the order they first appear (None as an empty cell)."""
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in keys})


# ----------------------------------------------------------------------------------------- why episodes end
#: the ends that are numerical: a bug of the simulator (or a result of an option documented as unstable)
NUMERICAL = ("numerical failure", "wing did not converge", "non-finite particle state", "non-finite state")
#: the conditions of :func:`end_reasons` below its overrides: winds 4-10 m/s, turbulence up to 0.15, starts anywhere
#: on the figure-eight
END_REASON_RANGES = ("env.wind_speed_min_mps=4", "env.wind_speed_max_mps=10", "env.turbulence_intensity_max=0.15",
                     "env.random_start=true")


def _episode_config(config, overrides, duration_s: float, seed: int):
    """The config ``kite-eval --randomize --duration D --seed S`` flies (its ``--set`` being ``overrides``)."""
    from kite_env.config import load_config
    from kite_env.flight import evaluation_config

    cfg = load_config(config, [*overrides, f"sim.duration_s={float(duration_s)!r}", f"wind.seed={seed}"])
    return evaluation_config(cfg, randomize=True)


def _end_reason_episode(job: tuple) -> dict:
    """One episode of :func:`end_reasons` in a fresh env: kite-eval's row; a numerical failure as a row ending
    "numerical failure" at its time (its message under ``failure``); a start that did not converge as ``error``."""
    policy, seed, episode, overrides, duration_s, config = job
    from kite_env.dynamics.simulator import NumericalFailure
    from kite_env.envs.figure_eight import KiteFigureEightEnv, StartError
    from kite_env.policies import make_agent

    env = KiteFigureEightEnv(config=_episode_config(config, overrides, duration_s, seed))
    agent = make_agent(policy, env, seed=seed)
    try:
        return evaluate_episode(env, agent, seed, episode)[2]
    except NumericalFailure as exc:  # a bug of the simulator: counted with its time and the episode's draws
        return {"episode": episode, "seed": seed, **env.episode_info, "termination_reason": "numerical failure",
                "sim_time_s": float(exc.t), "failure": str(exc)}
    except StartError as exc:
        return {"episode": episode, "seed": seed, "error": str(exc)}
    finally:
        env.close()


def end_reasons(episodes: int = 50, seed: int = 0, duration_s: float = 30.0, policy: str = "random", overrides=(),
                jobs: int = 1, config=None) -> dict:
    """Fly ``episodes`` randomised episodes of ``policy`` (seeds ``seed`` ..) in the conditions
    :data:`END_REASON_RANGES` then ``overrides`` (``config``: a YAML path or None), ``jobs`` processes at a time;
    returns ``{"episodes", "seed", "duration_s", "policy", "overrides", "rows", "failures", "table"}``: one row per
    episode by seed (kite-eval's columns), the message of each numerical failure by seed and the Markdown table
    (:func:`end_reasons_table`). A config or policy that is not one raises its ``ValueError`` (``ConfigError``,
    ``PolicyError``) before any episode flies; an episode whose start does not converge raises
    :class:`~kite_env.envs.figure_eight.StartError` naming its seed."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv, StartError
    from kite_env.policies import make_agent

    if episodes < 1 or jobs < 1 or not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError("episodes and jobs must be >= 1 and the duration > 0")
    sets = [*END_REASON_RANGES, *overrides]
    env = KiteFigureEightEnv(config=_episode_config(config, sets, duration_s, seed))  # bad input: raised here
    make_agent(policy, env, seed=seed)
    env.close()
    tasks = [(policy, s, s - seed, sets, duration_s, config) for s in range(seed, seed + episodes)]

    def check(row: dict) -> dict:
        if "error" in row:
            raise StartError(f"seed {row['seed']}: {row['error']}")
        return row

    if jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(jobs, episodes)) as pool:
            futures = [pool.submit(_end_reason_episode, t) for t in tasks]
            try:
                rows = [check(f.result()) for f in futures]
            except BaseException:
                for f in futures:
                    f.cancel()
                raise
    else:
        rows = [check(_end_reason_episode(t)) for t in tasks]
    failures = {int(r["seed"]): r.pop("failure") for r in rows if "failure" in r}
    rows.sort(key=lambda r: int(r["seed"]))
    result = {"episodes": len(rows), "seed": seed, "duration_s": float(duration_s), "policy": policy,
              "overrides": sets, "rows": rows, "failures": failures}
    result["table"] = end_reasons_table(result)
    return result


def end_reasons_table(result: dict) -> str:
    """The count of an :func:`end_reasons` result by end: episodes, kind (numerical, physical, none), median and
    shortest time of the end, then the winds drawn and the starts drawn again."""
    rows = result["rows"]
    reasons = Counter(r["termination_reason"] or "time limit" for r in rows)
    lines = [f"{len(rows)} episodes of {result['duration_s']:g} s, policy {result['policy']}, "
             f"`{' '.join(result['overrides'])}`", "",
             "| end | episodes | kind | median end [s] | shortest [s] |", "|---|---:|---|---:|---:|"]
    for reason, n in reasons.most_common():
        t = sorted(float(r["sim_time_s"]) for r in rows if (r["termination_reason"] or "time limit") == reason)
        kind = "numerical (a bug)" if reason in NUMERICAL else ("none" if reason in ("time limit", "completed")
                                                                  else "physical")
        lines.append(f"| {reason} | {n} | {kind} | {t[len(t) // 2]:.2f} | {t[0]:.2f} |")
    winds = sorted(float(r["wind_speed_mps"]) for r in rows)
    # a start that does not converge is drawn again by the env (env.reset_attempts): numerical too, counted here
    failed = sum(int(r.get("failed_starts") or 0) for r in rows)
    lines += ["", f"wind {winds[0]:.1f}-{winds[-1]:.1f} m/s; starts that did not converge (drawn again): {failed}"]
    return "\n".join(lines)


def write_end_reasons(result: dict, out: str | Path) -> Path:
    """Write an :func:`end_reasons` result into ``out``: ``episodes.csv`` (all episodes), ``end_reasons.md`` (the
    table) and, per numerical failure, ``failures/seed_N.log`` (its message with the wing solver's residual
    history)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_rows(out / "episodes.csv", result["rows"])
    (out / "end_reasons.md").write_text(result["table"] + "\n")
    for seed, text in result["failures"].items():
        (out / "failures").mkdir(exist_ok=True)
        (out / "failures" / f"seed_{seed}.log").write_text(text + "\n")
    return out


# ------------------------------------------------------------------------------------ the benchmark table
#: env id of each fidelity (the hyperparameter keys of kite-train)
BENCHMARK_ENV_IDS = {"surrogate": "KiteFigureEightFast-v1", "fe": "KiteFigureEight-v1"}
#: rl-baselines3-zoo's benchmark columns, then the physical metrics: (header, key of the row)
BENCHMARK_COLUMNS = [("algo", "algo"), ("env_id", "env_id"), ("mean_reward", "mean_reward"),
                     ("std_reward", "std_reward"), ("n_timesteps", "n_timesteps"), ("eval_episodes", "eval_episodes"),
                     ("tracking error RMS [deg]", "tracking_error_rms_deg"),
                     ("mean tether force [N]", "tether_force_mean_N"), ("crashes (n/N)", "crashes"),
                     ("mean flight time [s]", "flight_time_mean_s")]


def training_steps(model: Path) -> int | None:
    """Training steps of a saved SB3 model: ``num_timesteps`` of its zip, else ``timesteps`` of the run's
    ``args.yml`` next to it; None when neither is readable."""
    import yaml

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
    """One row of the benchmark from a kite-eval run's ``metrics.json`` dict (``spec``: the policy flown)."""
    from kite_env.policies import model_path

    rows = metrics.get("episode_rows") or [metrics]
    model = model_path(spec)
    steps = training_steps(model) if model is not None and model.is_file() else None
    return {"algo": label, "policy": spec, "fidelity": fidelity, "env_id": BENCHMARK_ENV_IDS[fidelity],
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
    heads = [h for h, _ in BENCHMARK_COLUMNS]
    align = ["---" if k in ("algo", "env_id", "n_timesteps", "crashes") else "---:" for _, k in BENCHMARK_COLUMNS]
    lines = ["| " + " | ".join(heads) + " |", "|" + "|".join(align) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r[k], k) for _, k in BENCHMARK_COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def recipe_env(recipe: str | Path) -> list[str]:
    """The ``env`` overrides of a training recipe's ``KiteFigureEightFast-v1`` entry as ``--set`` strings (the
    conditions its agent trained in; the training-only start rule ``table_only`` becomes ``table`` in every
    evaluation, :func:`kite_env.flight.evaluation_config`)."""
    from kite_env.training import FAST_ENV_ID, load_hyperparameters, recipe_overrides

    recipe = Path(recipe)
    algo = "sac" if recipe.stem == "sac" else "ppo"  # only the env entry is used
    return recipe_overrides(load_hyperparameters(recipe, algo, FAST_ENV_ID))


__all__ = ["BENCHMARK_COLUMNS", "BENCHMARK_ENV_IDS", "END_REASON_RANGES", "EPISODE_METRICS", "NUMERICAL",
           "benchmark_row", "benchmark_table", "end_reasons", "end_reasons_table", "evaluate_episode", "recipe_env",
           "training_steps", "write_end_reasons", "write_rows"]
