"""The paper's steering controller as a policy (Bosch et al., Sect. III.A, Eq. 14-15, Fig. 7-8).

Five steps (paper, Sect. III.A):

1. the point ``R*`` of the figure-eight nearest to the projected kite position ``R_k`` (geodesic distance ``delta``),
2. the unit tangent ``e_t`` and normal ``e_n`` of the path at ``R*`` (:class:`kite_env.trajectory.Lemniscate`),
3. the desired heading ``h* = beta e_t + (1 - beta) e_n`` (Eq. 14),
4. the heading angles ``psi*`` (of ``h*`` in the tangent plane at ``R*``) and ``psi`` (of the kite's nose ``-x_k``
   in the tangent plane at ``R_k``), both measured from ``x_s`` (:func:`kite_env.trajectory.heading_angle`),
5. ``dl* = K1 (psi* - psi)`` (Eq. 15), the desired steering-line length difference ``l_B - l_D``.

The K2 loops (Eq. 16-17) and the force controller (Eq. 18-19) that turn ``dl*`` into steering-line rest lengths
are the actuator model of the environment (:class:`kite_env.control.LineActuator`); together they are the paper's
flight controller of Fig. 8.

Sign: ``psi`` grows counter-clockwise about the outward normal (towards ``y_s``); the kite's right wing ``y_k``
points to decreasing ``psi``. Pulling the right steering line (``dl < 0``) turns the kite to its right, so a
positive heading error needs ``dl > 0``: K1 > 0.

Blending law (the paper's reference [16, 17] is not public; our design). The tangent weight
``beta = max(beta_min, 1 / (1 + (delta / delta_h)^2))`` with ``delta_h = control.beta_distance_deg`` scaled by
``max(v / 25 m/s, 0.5)``: on the path the kite heads along it (beta = 1); at ``delta_h`` it approaches at 45 deg;
far away it heads almost straight for it (beta -> beta_min). A faster kite turns on a larger radius
(for a given yaw rate), so it starts blending earlier: the distance scale grows with the speed.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.config import ControlConfig
from kite_env.trajectory import Lemniscate, heading_angle, wrap_angle

V_REF_MPS = 25.0  # speed at which the blending distance equals control.beta_distance_deg


class BaselinePolicy:
    """Heading controller of the paper: observation of the kite -> desired steering-line difference ``dl*`` [m]."""

    def __init__(self, cfg: ControlConfig, path: Lemniscate):
        self.cfg = cfg
        self.path = path
        self.s_hint: float | None = None

    def reset(self, s0: float | None = None) -> None:
        """Forget the path branch (``s0``: path parameter to start the search at, e.g. 0 at the crossing)."""
        self.s_hint = s0

    def blending(self, delta_rad: float, speed_mps: float) -> float:
        """Tangent weight beta of Eq. (14) for the distance ``delta`` to the path and the flight speed."""
        d_h = math.radians(self.cfg.beta_distance_deg) * max(speed_mps / V_REF_MPS, 0.5)
        return max(self.cfg.beta_min, 1.0 / (1.0 + (delta_rad / d_h) ** 2))

    def __call__(self, r_kcu: np.ndarray, nose: np.ndarray, v_kite: np.ndarray) -> tuple[float, dict]:
        """``dl*`` [m] and diagnostics for the KCU position ``r_kcu``, the nose direction ``-x_k`` and the velocity
        (all in W)."""
        R = np.asarray(r_kcu, dtype=float) / np.linalg.norm(r_kcu)
        near = self.path.nearest(R, self.s_hint)
        self.s_hint = near.s
        beta = self.blending(near.distance_rad, float(np.linalg.norm(v_kite)))
        h_star = beta * near.e_t + (1.0 - beta) * near.e_n  # Eq. (14)
        psi_star = float(heading_angle(near.point, h_star))
        psi = float(heading_angle(R, nose))
        err = float(wrap_angle(psi_star - psi))
        dl_star = self.cfg.k1_m_per_rad * err  # Eq. (15)
        return dl_star, {"s": near.s, "delta_rad": near.distance_rad, "beta": beta, "psi": psi,
                         "psi_star": psi_star, "heading_error": err}


class BaselineAgent:
    """The paper's controller behind Stable-Baselines3's ``predict`` interface, so that the baseline and trained
    agents go through one evaluation path (:class:`kite_env.envs.figure_eight.KiteFigureEightEnv` observations).

    It reads the raw (not normalised) observation: the terms ``position``, ``heading`` and ``rates`` (for the speed
    of the blending law) must be in ``env.observation``; ``path`` (its phase) picks the branch of the figure-eight at
    the first step of an episode, as :func:`kite_env.flight.fly` does with the start parameter. The action is
    ``dl* / control.delta_l_max_m`` clipped to [-1, 1]. One controller state per environment of a vectorised batch.
    """

    REQUIRED = ("position", "heading", "rates")

    def __init__(self, cfg, path: Lemniscate | None = None):
        from kite_env.envs.figure_eight import V_SCALE_MPS, observation_layout

        self.cfg = cfg
        self.path = path if path is not None else Lemniscate(cfg.trajectory)
        self.layout = observation_layout(cfg.env.observation)
        missing = [t for t in self.REQUIRED if t not in self.layout]
        if missing:
            raise ValueError(f"the baseline needs the observation terms {', '.join(missing)} (env.observation is "
                             f"{cfg.env.observation!r})")
        self.v_scale = V_SCALE_MPS
        self._ctrl: list[BaselinePolicy] = []
        self._fresh: list[bool] = []

    def _ensure(self, n: int) -> None:
        while len(self._ctrl) < n:
            self._ctrl.append(BaselinePolicy(self.cfg.control, self.path))
            self._fresh.append(True)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        from kite_env.trajectory import sphere_basis

        obs = np.asarray(observation, dtype=float)
        single = obs.ndim == 1
        obs = np.atleast_2d(obs)
        n = obs.shape[0]
        self._ensure(n)
        if episode_start is not None:
            for i, start in enumerate(np.broadcast_to(np.asarray(episode_start, dtype=bool), (n,))):
                if start:
                    self._fresh[i] = True
        lay = self.layout
        act = np.empty((n, 1), dtype=np.float32)
        for i in range(n):
            R = obs[i, lay["position"]]
            R = R / np.linalg.norm(R)
            sin_psi, cos_psi = obs[i, lay["heading"]]
            speed = float(obs[i, lay["rates"]][3]) * self.v_scale
            if self._fresh[i]:
                s0 = None
                if "path" in lay:
                    ph = obs[i, lay["path"]]
                    s0 = float(math.atan2(ph[3], ph[4])) % (2.0 * math.pi)
                self._ctrl[i].reset(s0)
                self._fresh[i] = False
            x_s, y_s = sphere_basis(R)
            nose = cos_psi * x_s + sin_psi * y_s
            dl, _ = self._ctrl[i](R, nose, speed * nose)
            act[i, 0] = np.clip(dl / self.cfg.control.delta_l_max_m, -1.0, 1.0)
        return (act[0] if single else act), None
