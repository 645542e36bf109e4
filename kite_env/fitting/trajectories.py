"""Flights of the full model recorded step by step: the data the reduced-order wing of the wing with inertia is
fitted to.

The wing with inertia (``structure.dynamic``) has a state of its own (1332 DOF, their rates, the downwash): the force
it exerts on the bridle points A-D at a time depends on how it got there, not only on where A-D are. Its
reduced-order model is therefore fitted to whole trajectories rather than to static solves: :class:`FlightTape`,
attached to :class:`kite_env.envs.figure_eight.KiteFigureEightEnv` as its recorder, keeps every physics step of an
episode (rows of :data:`COLUMNS`), and :func:`sample_flights` flies the episodes of a sampling plan, one ``.npz``
file each, so that an interrupted run keeps what it flew and can go on.

What a row holds (frame W unless noted, SI units): the time; positions, velocities and, for the wing with inertia,
accelerations of A, B, C, D (the wing's nodes) and the KCU; the steering lines' rest lengths; the tether length,
reel-out speed and force; the bridle-line tensions; the wind at the five masses and at the frame origin; the angles
of attack of the right tip, mid and left tip sections, lift and drag; the wing solver's Newton iterations.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kite_env.surrogate.samples import git_commit

#: per-row arrays of a tape and their shapes per row
COLUMNS = {"t": (), "r": (5, 3), "v": (5, 3), "a": (5, 3), "rest": (4,), "tether_length": (), "reel_speed": (),
           "tether_force": (), "tension": (4,), "wind": (6, 3), "alpha": (3,), "lift": (), "drag": (),
           "newton": (), "action": ()}


class FlightTape:
    """Recorder (``env.recorder``) that keeps every physics step of an episode (module docstring).

    The accelerations of A-D are the wing's own (the generalized-alpha state of the wing with inertia, the
    acceleration of its nodes at the end of the step); the KCU's is its velocity change over the step. The
    quasi-static wing and the fast fidelity have no wing acceleration: A-D's are then their velocity change too.
    """

    def __init__(self):
        self.rows: dict[str, list] = {k: [] for k in COLUMNS}
        self._action = 0.0
        self.sim = None

    # the recorder interface of KiteFigureEightEnv
    def start(self, sim, rec, s0, L_B, L_D, mu) -> None:
        self.sim = sim
        self.rows = {k: [] for k in COLUMNS}
        self._prev = None
        self._row(rec, L_B, L_D)

    def record(self, rec, L_B, L_D, ainfo, t_step) -> None:
        self._row(rec, L_B, L_D)

    def set_action(self, a: float) -> None:
        """The normalised action of the control step now flown (stored with its physics steps)."""
        self._action = float(a)

    def _row(self, rec, L_B, L_D) -> None:
        r, v = rec.state.r, rec.state.v
        a = np.full((5, 3), np.nan)
        if self._prev is not None and rec.t > self._prev[0]:
            a[:] = (v - self._prev[1]) / (rec.t - self._prev[0])
        dyn = getattr(self.sim, "dyn", None)
        if dyn is not None and getattr(self.sim, "fidelity_now", "fe") == "fe":
            a[:4] = dyn.a[dyn.bridle] @ rec.R_wk.T  # inertial accelerations of the wing's nodes A-D, in W
        self._prev = (rec.t, v.copy())
        origin = 0.5 * (r[0] + r[2])
        wind = np.asarray(self.sim.wind.velocity(rec.t, np.vstack([r, origin[None, :]])), dtype=float)
        al = np.asarray(rec.wing.alpha, float)
        alpha = np.array([al[0], al[len(al) // 2], al[-1]]) if al.size > 3 else al
        rest = np.array([np.nan, L_B, np.nan, L_D])
        w = self.rows
        w["t"].append(rec.t)
        w["r"].append(r.copy())
        w["v"].append(v.copy())
        w["a"].append(a)
        w["rest"].append(rest)
        w["tether_length"].append(rec.tether_length)
        w["reel_speed"].append(rec.reel_speed)
        w["tether_force"].append(rec.tether_force)
        w["tension"].append(np.asarray(rec.line_tension, float).copy())
        w["wind"].append(wind)
        w["alpha"].append(alpha)
        w["lift"].append(float(rec.wing.lift))
        w["drag"].append(float(rec.wing.drag))
        w["newton"].append(int(getattr(rec.wing, "newton_iters", 0)))
        w["action"].append(self._action)

    def arrays(self) -> dict[str, np.ndarray]:
        out = {}
        for k, shape in COLUMNS.items():
            out[k] = np.asarray(self.rows[k], dtype=float).reshape((len(self.rows[k]), *shape))
        power = self.sim.particles.rest[0] if self.sim is not None and self.sim.particles is not None else np.nan
        out["rest"][:, 0] = out["rest"][:, 2] = power
        return out


def save_tape(path: str | Path, arrays: dict, meta: dict) -> Path:
    """One episode's tape as a compressed ``.npz`` (written to a temporary name, then renamed: a file that exists is
    whole)."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".part.npz")
    np.savez_compressed(tmp, meta=json.dumps(meta), **arrays)
    tmp.replace(path)
    return path


def tape_paths(tape_dir: str | Path) -> list[Path]:
    """The whole tapes of a folder (``ep_*.npz``, sorted; not the ``.part.npz`` that :func:`save_tape` is writing)."""
    return [p for p in sorted(Path(tape_dir).glob("ep_*.npz")) if not p.name.endswith(".part.npz")]


def load_tape(path: str | Path) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a tape written by :func:`save_tape`."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files if k != "meta"}, json.loads(str(z["meta"]))


# ---------------------------------------------------------------------------------------------------- policies
class HeldNoise:
    """A sampling policy: ``base`` (or 0) plus a random offset held for a random time, uniform in
    ``[-amp, amp]``, each held ``hold_s`` (uniform in the given range) [s] (a pilot's or an exploring agent's
    deliberate inputs, slower than ``random``'s new action every control step)."""

    def __init__(self, base, amp: float, hold_s: tuple[float, float], control_dt: float, rng: np.random.Generator):
        self.base, self.amp, self.hold, self.dt, self.rng = base, float(amp), hold_s, float(control_dt), rng
        self._left, self._offset = 0.0, 0.0

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        if episode_start is not None and bool(np.asarray(episode_start).ravel()[0]):
            self._left = 0.0
        if self._left <= 0.0:
            self._offset = float(self.rng.uniform(-self.amp, self.amp))
            self._left = float(self.rng.uniform(*self.hold))
        self._left -= self.dt
        a = 0.0
        if self.base is not None:
            a = float(np.asarray(self.base.predict(observation, state, episode_start, deterministic)[0]).ravel()[0])
        return np.array([min(1.0, max(-1.0, a + self._offset))], dtype=np.float32), None


class HeldDepower:
    """Held random offsets on the common length of both steering lines (``LineActuator.depower_offset_m``, on top of
    the force loop's L3, Eq. 16-17): uniform in ``[-amp, amp]`` [m], each held ``hold_s`` (uniform in the given
    range) [s].

    Why: in a flight of the paper's controller the force loop sets the common length of the steering lines from the
    force ratio mu, so recorded flights tie the wing's depower shape to the load that moved it, and a wing fitted to
    them cannot tell cause from effect; it answers depower several times too strongly (docs/fast_fidelity.md, "Why
    the fast kite leaves its envelope at low wind"). An excitation the loop does not make, added to the controller's
    output, makes the closed loop's data informative (Ljung, System Identification: Theory for the User, 2nd ed.,
    1999, Ch. 13). ``update(actuator)`` once per controller period, before the env's step."""

    def __init__(self, amp: float, hold_s: tuple[float, float], control_dt: float, rng: np.random.Generator):
        self.amp, self.hold, self.dt, self.rng = float(amp), hold_s, float(control_dt), rng
        self._left, self.offset = 0.0, 0.0

    def update(self, actuator) -> None:
        if self._left <= 0.0:
            self.offset = float(self.rng.uniform(-self.amp, self.amp))
            self._left = float(self.rng.uniform(*self.hold))
        self._left -= self.dt
        actuator.depower_offset_m = self.offset


@dataclass
class EpisodePlan:
    """One sampled flight: the policy, its conditions and its seed."""

    index: int
    policy: str  # baseline | random | constant:<a> | held:<amp> | <policy>+held:<amp> | an agent; +depower:<m>
    wind_mps: float
    turbulence_max: float
    gust_mps: float
    gust_start_s: float
    duration_s: float
    seed: int

    def overrides(self) -> list[str]:
        over = [f"env.wind_speed_min_mps={self.wind_mps}", f"env.wind_speed_max_mps={self.wind_mps}",
                f"env.turbulence_intensity_max={self.turbulence_max}", "env.random_start=true",
                "env.start_curvature_max=1.0", "env.initial_speed_per_wind_min=4.0",
                "env.initial_speed_per_wind_max=4.8", f"env.max_episode_s={self.duration_s}"]
        if self.gust_mps > 0.0:
            over += [f"wind.gust_speed_mps={self.gust_mps}", f"wind.gust_start_s={self.gust_start_s}",
                     "wind.gust_duration_s=4.0"]
        return over


def sampling_plan(n: int, seed: int, winds=(4.0, 10.0)) -> list[EpisodePlan]:
    """``n`` episodes drawn from ``seed``: winds uniform in ``winds`` [m/s], turbulence intensity up to 0.1 (drawn
    by the env from 0 to it), a 4 s gust of up to 6 m/s in one episode of four; the policies in turn: the baseline
    (60 s), the baseline with held offsets (40 s), held random inputs, white random actions and constant steering
    (20 s each: most of these end on the ground well before)."""
    rng = np.random.default_rng(seed)
    kinds = ("baseline", "baseline+held", "held", "random", "constant", "baseline+held")
    plan = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        if kind == "baseline":
            pol, dur = "baseline", 60.0
        elif kind == "baseline+held":
            pol, dur = f"baseline+held:{rng.uniform(0.1, 0.5):.3f}", 40.0
        elif kind == "held":
            pol, dur = f"held:{rng.uniform(0.2, 1.0):.3f}", 20.0
        elif kind == "random":
            pol, dur = "random", 20.0
        else:
            pol, dur = f"constant:{rng.choice([-1, 1]) * rng.uniform(0.05, 0.8):.3f}", 20.0
        gust = float(rng.uniform(2.0, 6.0)) if rng.uniform() < 0.25 else 0.0
        plan.append(EpisodePlan(i, pol, round(float(rng.uniform(*winds)), 3), 0.1, round(gust, 3),
                                round(float(rng.uniform(3.0, 0.6 * dur)), 2), dur, int(rng.integers(2**31 - 1))))
    return plan


#: index of the first start episode (:func:`start_plan`): apart from the flights of :func:`sampling_plan`
START_INDEX = 10_000


def start_plan(n: int, seed: int, winds=(4.0, 10.0)) -> list[EpisodePlan]:
    """``n`` short episodes (3 s) of starts, indexed from :data:`START_INDEX`: the first second after a reset is a
    transient of its own (the wing released from its static shape at 4-5 times the wind) that the long flights sample
    once each; the paper's controller and the controller with held offsets in turn, in the conditions of
    :func:`sampling_plan`."""
    rng = np.random.default_rng(seed)
    plan = []
    for i in range(n):
        pol = "baseline" if i % 2 == 0 else f"baseline+held:{rng.uniform(0.1, 0.5):.3f}"
        plan.append(EpisodePlan(START_INDEX + i, pol, round(float(rng.uniform(*winds)), 3), 0.1, 0.0, 0.0, 3.0,
                                int(rng.integers(2**31 - 1))))
    return plan


#: index of the first flight of :func:`depower_plan`: apart from those of the other plans
DEPOWER_INDEX = 30_000


def depower_plan(n: int, seed: int, winds=(4.0, 10.0)) -> list[EpisodePlan]:
    """``n`` flights of 40 s with held random offsets of up to 0.05-0.2 m on the force loop's common increment
    (:class:`HeldDepower`), indexed from :data:`DEPOWER_INDEX`: the paper's controller, and the controller with held
    steering offsets of up to 0.1-0.5, in turn, in the conditions of :func:`sampling_plan` (the common length of the
    sampled flights moves by 0.1-0.17 m RMS under the loop alone)."""
    rng = np.random.default_rng(seed)
    plan = []
    for i in range(n):
        dep = f"+depower:{rng.uniform(0.05, 0.2):.3f}"
        pol = "baseline" + dep if i % 2 == 0 else f"baseline+held:{rng.uniform(0.1, 0.5):.3f}" + dep
        gust = float(rng.uniform(2.0, 6.0)) if rng.uniform() < 0.25 else 0.0
        plan.append(EpisodePlan(DEPOWER_INDEX + i, pol, round(float(rng.uniform(*winds)), 3), 0.1, round(gust, 3),
                                round(float(rng.uniform(3.0, 24.0)), 2), 40.0, int(rng.integers(2**31 - 1))))
    return plan


#: index of the first flight of a trained agent (:func:`agent_plan`): apart from those of the other plans
AGENT_INDEX = 20_000


def agent_plan(n: int, seed: int, agent: str, winds=(4.0, 10.0)) -> list[EpisodePlan]:
    """``n`` flights of a trained ``agent`` (a shipped name or a ``model.zip``), indexed from :data:`AGENT_INDEX`:
    the agent alone (60 s) and the agent with held offsets of up to 0.1-0.4 (40 s) in turn, in the conditions of
    :func:`sampling_plan`. An agent trained in the fast fidelity steers the kite through states that the paper's
    controller and the random inputs of :func:`sampling_plan` do not reach; a wing fitted without them answers its
    steering as it never learnt to (docs/fast_fidelity.md), so its flights belong in the samples (the data-aggregation
    idea of Ross, Gordon & Bagnell, "A reduction of imitation learning and structured prediction to no-regret online
    learning", AISTATS 2011, applied to the model the agent trains in)."""
    rng = np.random.default_rng(seed)
    plan = []
    for i in range(n):
        if i % 2 == 0:
            pol, dur = agent, 60.0
        else:
            pol, dur = f"{agent}+held:{rng.uniform(0.1, 0.4):.3f}", 40.0
        gust = float(rng.uniform(2.0, 6.0)) if rng.uniform() < 0.25 else 0.0
        plan.append(EpisodePlan(AGENT_INDEX + i, pol, round(float(rng.uniform(*winds)), 3), 0.1, round(gust, 3),
                                round(float(rng.uniform(3.0, 0.6 * dur)), 2), dur, int(rng.integers(2**31 - 1))))
    return plan


def make_sampling_policy(spec: str, env, seed: int):
    """The policy of an :class:`EpisodePlan` for ``env``: a policy of :func:`kite_env.policies.make_agent`,
    ``held:<amp>`` or ``<policy>+held:<amp>``."""
    from kite_env.policies import make_agent

    rng = np.random.default_rng(seed)
    if "+held:" in spec:
        base, amp = spec.rsplit("+held:", 1)
        return HeldNoise(make_agent(base, env, seed=seed), float(amp), (0.2, 1.5), env.control_dt, rng)
    if spec.startswith("held:"):
        return HeldNoise(None, float(spec.split(":")[1]), (0.1, 1.0), env.control_dt, rng)
    return make_agent(spec, env, seed=seed)


def fly_plan(plan: EpisodePlan, base_overrides=(), tape: FlightTape | None = None):
    """Fly one planned episode of the full model; returns ``(arrays, meta)``."""
    from kite_env.config import fingerprint
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    env = KiteFigureEightEnv(overrides=[*base_overrides, *plan.overrides()])
    tape = tape or FlightTape()
    env.recorder = tape
    policy, depower = plan.policy, None
    if "+depower:" in policy:
        policy, amp = policy.rsplit("+depower:", 1)
        depower = HeldDepower(float(amp), (0.2, 1.5), env.control_dt, np.random.default_rng([plan.seed, 1]))
    agent = make_sampling_policy(policy, env, plan.seed)
    if hasattr(agent, "seed_episode"):
        agent.seed_episode(plan.seed)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=plan.seed)
    start, done, reason, info = True, False, None, dict(info)
    while not done:
        act, _ = agent.predict(obs, episode_start=np.array([start]), deterministic=True)
        start = False
        tape.set_action(float(np.asarray(act).ravel()[0]))
        if depower is not None:
            depower.update(env.actuator)
        obs, _, term, trunc, step_info = env.step(act)
        info.update(step_info)
        done = term or trunc
        reason = step_info.get("termination_reason")
    arrays = tape.arrays()
    meta = {"plan": plan.__dict__, "episode": {k: info[k] for k in ("wind_speed_mps", "turbulence_intensity",
                                                                     "wind_seed", "start_s", "initial_speed_mps")},
            "end": reason or "completed", "flown_s": float(arrays["t"][-1] - arrays["t"][0]),
            "wall_s": time.perf_counter() - t0, "rows": int(len(arrays["t"])), "model": fingerprint(env.cfg),
            "overrides": [*base_overrides, *plan.overrides()], "git_commit": git_commit()}
    env.close()
    return arrays, meta


def sample_flights(out_dir: str | Path, n: int, seed: int, base_overrides=(), start: int = 0, step: int = 1,
                   log=print, starts: bool = False, agent: str | None = None,
                   depower: bool = False) -> list[Path]:
    """Fly the episodes ``start, start + step, ...`` of ``sampling_plan(n, seed)`` (``starts``: of
    :func:`start_plan`; ``agent``: of :func:`agent_plan`; ``depower``: of :func:`depower_plan`) into
    ``out_dir/ep_XXXX.npz``, skipping those already there (an interrupted run goes on where it stopped; several
    processes share a plan with distinct ``start`` and the same ``step``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    if agent is not None:
        plans = agent_plan(n, seed, agent)
    elif depower:
        plans = depower_plan(n, seed)
    else:
        plans = (start_plan if starts else sampling_plan)(n, seed)
    for plan in plans[start::step]:
        path = out / f"ep_{plan.index:04d}.npz"
        paths.append(path)
        if path.is_file():
            continue
        arrays, meta = fly_plan(plan, base_overrides)
        save_tape(path, arrays, meta)
        log(f"{plan.index:4d} {plan.policy:<22} {plan.wind_mps:5.2f} m/s gust {plan.gust_mps:4.1f}  "
            f"{meta['flown_s']:6.2f} s  {meta['end']:<14} wall {meta['wall_s']:6.1f} s "
            f"({meta['wall_s'] / max(meta['flown_s'], 1e-9):.2f} per s)")
    return paths


__all__ = ["AGENT_INDEX", "COLUMNS", "DEPOWER_INDEX", "START_INDEX", "EpisodePlan", "FlightTape", "HeldDepower",
           "HeldNoise", "agent_plan", "depower_plan", "fly_plan", "load_tape", "make_sampling_policy", "sample_flights",
           "sampling_plan", "save_tape", "start_plan"]
