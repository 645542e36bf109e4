"""Wind field in the wind frame W: mean profile + frozen von Kármán turbulence + a 1-cosine gust.

Frame W (paper, Sect. II): origin at the tether's ground attachment, ``x_w`` along the mean wind, ``z_w`` up.
The paper itself flies in a uniform wind of 5 m/s (Fig. 9); profile, turbulence and gust are extensions
(the paper names gust loads as an important extension, end of Sect. IV).

Mean wind (along ``x_w``, depends on the height ``z = r_z`` only)
    uniform: ``U(z) = U_ref``
    log:     ``U(z) = U_ref ln(z / z0) / ln(z_ref / z0)``, with ``z`` clipped to ``>= z0`` (zero at and below ``z0``)
    power:   ``U(z) = U_ref (z / z_ref)^a``, with ``z`` clipped to ``>= 0`` (zero at and below the ground)
``U_ref = speed_mps`` at ``z_ref = ref_height_m``. Default roughness ``z0 = 0.0002 m`` and the log law follow the
wind-profile defaults of KiteUtils.jl (OpenSourceAWE/KiteUtils.jl, data/settings.yaml); ``a = 0.14`` is the usual
open-terrain power-law
exponent (modelling choice; KiteUtils.jl uses 0.08163 in Fechner's setting).

Turbulence (frozen field, Taylor's hypothesis)
    ``u_j(t, r) = sum_n A_jn cos(k_jn . (r - U_ref t e_x) + theta_jn)``,  ``j = u, v, w`` (components along W)
Each component has its own ``M = turbulence_modes`` modes. The longitudinal wavenumbers ``k1 = k_jn,x > 0`` are
stratified in ``ln k1`` over ``[K1_MIN/L, K1_MAX/L]`` (one uniformly jittered sample per bin of width
``dln = ln(K1_MAX/K1_MIN)/M``); the amplitudes follow the one-sided von Kármán spectra of the gust model in
MIL-F-8785C / MIL-HDBK-1797 (as stated e.g. in the MathWorks Aerospace Blockset "Von Karman Wind Turbulence
Model"), written for isotropic turbulence (``sigma_u = sigma_v = sigma_w``, transverse scales ``L_v = L_w = L/2``)
in terms of the longitudinal integral length scale ``L = turbulence_length_m``:
    ``F_u(k1) = sigma^2 (2 L / pi) / (1 + (1.339 L k1)^2)^(5/6)``
    ``F_v(k1) = F_w(k1) = sigma^2 (L / pi) (1 + 8/3 (1.339 L k1)^2) / (1 + (1.339 L k1)^2)^(11/6)``
    ``A_jn^2 / 2 = F_j(k1_n) k1_n dln``, then every component is rescaled so that ``sum_n A_jn^2 / 2 = sigma^2``
    exactly, ``sigma = turbulence_intensity * speed_mps``.
With Taylor's hypothesis a fixed point sees mode ``n`` at the angular frequency ``k1_n U_ref``; all frequencies are
positive and distinct, so the time variance at any point equals ``sigma^2`` (the test checks it statistically).
The transverse wavenumber of each mode (modelling choice, not a full 3-D spectral tensor) has the magnitude
``sqrt(k1^2 + (1/(1.339 L))^2)`` and a uniformly random direction in the ``y_w``-``z_w`` plane: small eddies are
about as wide as long, the largest ones keep a coherence length of order ``L`` across the wind. The field is not
divergence free and has no Reynolds stress (``u``, ``v``, ``w`` are independent), and its intensity does not
depend on height.

Gust (1-cosine, uniform in space, along ``x_w``)
    ``g(t) = G/2 (1 - cos(2 pi (t - t0) / T))`` for ``t0 <= t <= t0 + T``, else 0;  ``G = gust_speed_mps``
    (a negative ``G`` gives a lull).

Randomness: everything random is drawn once in ``WindField.__init__`` from ``np.random.default_rng(seed)``; the same
seed gives bit-identical velocities (for one backend on one machine), a different seed another realisation.

Cost (shared 2-core development container, 64 modes, 10 points, one :meth:`WindField.velocity` call): ~28 us with
the compiled (numba) mode sum, ~95 us with the NumPy reference (dominated by ``np.cos`` of 1920 phases); without
turbulence ~12 us. The first use of the numba kernel in a fresh checkout compiles it (~2 s, cached in
``__pycache__`` afterwards).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from kite_env.compiled import njit, resolve_backend  # without numba the NumPy path is used

PROFILES = ("uniform", "log", "power")
K1_MIN = 0.02  # lowest longitudinal wavenumber of the turbulence modes, times L [-]
K1_MAX = 500.0  # highest longitudinal wavenumber of the turbulence modes, times L [-]
VK_A = 1.339  # von Kármán spectral constant (MIL-F-8785C form) [-]
_TWO_PI = 2.0 * math.pi
_INV_TWO_PI = 1.0 / _TWO_PI
# Taylor coefficients (-1)^k / (2k)! of cos, k = 0..13: |error| < 2e-15 on [-pi, pi]. A literal tuple, not a
# computed array: numba's cache is keyed on this file only.
_COS_TAYLOR = (
    1.0, -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0, 1.0 / 479001600.0,
    -1.0 / 87178291200.0, 1.0 / 20922789888000.0, -1.0 / 6402373705728000.0, 1.0 / 2432902008176640000.0,
    -1.0 / 1124000727777607680000.0, 1.0 / 620448401733239439360000.0, -1.0 / 403291461126605635584000000.0,
)


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract", "nsz"})
def _turbulence_kernel(t, pos, wavevec_t, phase0, omega, amp, n_modes, out):  # pragma: no cover - compiled
    """Compiled sum of the Fourier modes (same quantity as the NumPy path of :meth:`WindField._turbulence`).

    ``t (1,) or (n,)``, ``pos (n, 3)``, ``wavevec_t (3, 3m)``, ``phase0, omega, amp (3m,)``, ``out (n, 3)``.
    The cosine of the phase reduced to [-pi, pi] is a Taylor polynomial (Horner in a^2), which the compiler
    vectorises; reassociation is allowed, so sums may differ from the NumPy path in the last bits.
    """
    n = pos.shape[0]
    nm = wavevec_t.shape[1]
    nt = t.shape[0]
    phase_t = np.empty(nm)
    for i in range(n):
        if i == 0 or nt > 1:
            ti = t[i] if nt > 1 else t[0]
            for j in range(nm):
                p = phase0[j] - omega[j] * ti
                phase_t[j] = p - _TWO_PI * math.floor(p * _INV_TWO_PI)
        x = pos[i, 0]
        y = pos[i, 1]
        z = pos[i, 2]
        for c in range(3):
            acc = 0.0
            for j in range(c * n_modes, (c + 1) * n_modes):
                a = wavevec_t[0, j] * x + wavevec_t[1, j] * y + wavevec_t[2, j] * z + phase_t[j]
                a -= _TWO_PI * math.floor(a * _INV_TWO_PI + 0.5)
                a2 = a * a
                q = _COS_TAYLOR[13]
                for k in range(12, -1, -1):
                    q = q * a2 + _COS_TAYLOR[k]
                acc += amp[j] * q
            out[i, c] = acc
    return out


@dataclass(frozen=True)
class WindConfig:
    speed_mps: float = 5.0  # mean wind speed at the reference height (paper, Fig. 9) [m/s]
    profile: str = "uniform"  # mean profile: uniform | log | power
    ref_height_m: float = 10.0  # reference height of speed_mps [m]
    roughness_m: float = 0.0002  # log-law roughness length z0 (KiteUtils.jl's default) [m]
    shear_exponent: float = 0.14  # power-law exponent a [-]
    turbulence_intensity: float = 0.0  # sigma_u / speed_mps [-]
    turbulence_length_m: float = 100.0  # longitudinal integral length scale L [m]
    turbulence_modes: int = 64  # Fourier modes per velocity component [-]
    gust_speed_mps: float = 0.0  # 1-cosine gust amplitude along x_w (negative: lull) [m/s]
    gust_start_s: float = 0.0  # gust start time t0 [s]
    gust_duration_s: float = 0.0  # gust duration T [s]
    seed: int = 0  # seed of the turbulence realisation [-]

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first invalid field (``wind.<field> ...``)."""
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"wind.{f.name} must be finite, got {v!r}")
        if self.speed_mps < 0:
            raise ValueError(f"wind.speed_mps must be >= 0, got {self.speed_mps!r}")
        if self.profile not in PROFILES:
            raise ValueError(f"wind.profile must be one of {', '.join(PROFILES)}, got {self.profile!r}")
        if not self.ref_height_m > 0:
            raise ValueError(f"wind.ref_height_m must be positive, got {self.ref_height_m!r}")
        if not 0 < self.roughness_m < self.ref_height_m:
            raise ValueError(f"wind.roughness_m must lie in (0, ref_height_m), got {self.roughness_m!r}")
        if not 0 <= self.shear_exponent < 1:
            raise ValueError(f"wind.shear_exponent must lie in [0, 1), got {self.shear_exponent!r}")
        if self.turbulence_intensity < 0:
            raise ValueError(f"wind.turbulence_intensity must be >= 0, got {self.turbulence_intensity!r}")
        if not self.turbulence_length_m > 0:
            raise ValueError(f"wind.turbulence_length_m must be positive, got {self.turbulence_length_m!r}")
        if self.turbulence_modes < 1:
            raise ValueError(f"wind.turbulence_modes must be >= 1, got {self.turbulence_modes!r}")
        if self.gust_duration_s < 0:
            raise ValueError(f"wind.gust_duration_s must be >= 0, got {self.gust_duration_s!r}")
        if self.gust_speed_mps != 0 and self.gust_duration_s == 0:
            raise ValueError("wind.gust_duration_s must be positive when wind.gust_speed_mps is not 0")
        if self.seed < 0:
            raise ValueError(f"wind.seed must be >= 0, got {self.seed!r}")


def von_karman_spectra(k1: np.ndarray, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided von Kármán spectra per unit variance, isotropic form (see module docstring).

    Parameters
    ----------
    k1 : (n,) float [rad/m], longitudinal wavenumber
    length_m : float [m], longitudinal integral length scale L

    Returns
    -------
    f_u, f_t : (n,) float [m/rad], longitudinal and transverse spectra; each integrates to 1 over ``k1 in (0, inf)``
    """
    x2 = (VK_A * length_m * np.asarray(k1, dtype=float)) ** 2
    f_u = (2.0 * length_m / np.pi) / (1.0 + x2) ** (5.0 / 6.0)
    f_t = (length_m / np.pi) * (1.0 + 8.0 / 3.0 * x2) / (1.0 + x2) ** (11.0 / 6.0)
    return f_u, f_t


class WindField:
    """Wind velocity ``v_w(t, r)`` in frame W for a :class:`WindConfig`.

    Parameters
    ----------
    cfg : WindConfig
    seed : int or None
        Overrides ``cfg.seed`` when given (e.g. the environment's episode seed).
    backend : {"auto", "numba", "numpy"}
        How the turbulence modes are summed: ``"numpy"`` is the reference (``np.cos`` in float64), ``"numba"`` a
        compiled loop with a polynomial cosine (agrees with the reference to ~1e-14 of the amplitudes, about 4x
        faster at 10 points), ``"auto"`` as every compiled kernel (:func:`kite_env.compiled.resolve_backend`: the
        environment variable ``KITE_ENV_ELEMENT_BACKEND`` if set, else numba when it can be imported).
    """

    def __init__(self, cfg: WindConfig, seed: int | None = None, backend: str = "auto") -> None:
        if not isinstance(cfg, WindConfig):
            raise TypeError(f"cfg must be a WindConfig, got {type(cfg).__name__}")
        cfg.validate()
        if seed is not None and (int(seed) != seed or seed < 0):
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.backend = resolve_backend(backend)
        self.cfg = cfg
        self.seed = int(cfg.seed if seed is None else seed)
        self.sigma = cfg.turbulence_intensity * cfg.speed_mps  # target std of every component [m/s]
        self._u_adv = cfg.speed_mps  # Taylor advection speed: mean wind at the reference height [m/s]
        self._log_den = math.log(cfg.ref_height_m / cfg.roughness_m)
        self._build_modes()

    # ------------------------------------------------------------------ turbulence modes
    def _build_modes(self) -> None:
        cfg = self.cfg
        m = cfg.turbulence_modes
        length = cfg.turbulence_length_m
        rng = np.random.default_rng(self.seed)
        # draws happen even without turbulence, so the random stream does not depend on the intensity
        dln = math.log(K1_MAX / K1_MIN) / m
        ln_k1 = math.log(K1_MIN / length) + (np.arange(m)[None, :] + rng.random((3, m))) * dln  # (3, m)
        k1 = np.exp(ln_k1)
        k_perp = np.sqrt(k1**2 + (1.0 / (VK_A * length)) ** 2)
        ang = rng.uniform(0.0, 2.0 * np.pi, (3, m))
        theta = rng.uniform(0.0, 2.0 * np.pi, (3, m))
        wavevec = np.stack([k1, k_perp * np.cos(ang), k_perp * np.sin(ang)], axis=-1)  # (3, m, 3) [rad/m]
        f_u, f_t = von_karman_spectra(k1.ravel(), length)
        spec = np.where(np.arange(3)[:, None] == 0, f_u.reshape(3, m), f_t.reshape(3, m))
        half_a2 = spec * k1 * dln  # A^2/2 per mode, per unit variance
        half_a2 /= half_a2.sum(axis=1, keepdims=True)  # exact variance sigma^2 per component
        amp = np.sqrt(2.0 * half_a2) * self.sigma  # (3, m) [m/s]
        self.turbulent = bool(self.sigma > 0.0)
        self.k1 = k1  # (3, m) [rad/m], kept for inspection
        self.amplitude = amp  # (3, m) [m/s]
        # the 3m Fourier modes flattened (read by the fast fidelity, which sums them for all its kites in one kernel)
        self.wavevec_t = np.ascontiguousarray(wavevec.reshape(3 * m, 3).T)  # (3, 3m) [rad/m]
        self.omega = wavevec[..., 0].reshape(3 * m) * self._u_adv  # angular frequency at a fixed point [rad/s]
        self.phase0 = theta.reshape(3 * m)  # [rad]
        self.amp = amp.reshape(3 * m)

    # ------------------------------------------------------------------ public API
    def mean_speed(self, z: np.ndarray | float) -> np.ndarray:
        """Mean wind speed along ``x_w`` at height ``z`` (profile only, no turbulence or gust).

        Parameters
        ----------
        z : float or (n,) float [m], height above the ground (``r_z`` in W)

        Returns
        -------
        (n,) float or float [m/s]
        """
        cfg = self.cfg
        z = np.asarray(z, dtype=float)
        if cfg.profile == "uniform":
            return np.full_like(z, cfg.speed_mps)
        if cfg.profile == "log":
            zc = np.maximum(z, cfg.roughness_m)
            return cfg.speed_mps * np.log(zc / cfg.roughness_m) / self._log_den
        zc = np.maximum(z, 0.0)
        return cfg.speed_mps * (zc / cfg.ref_height_m) ** cfg.shear_exponent

    def gust(self, t: np.ndarray | float) -> np.ndarray | float:
        """1-cosine gust speed along ``x_w`` [m/s] at time ``t`` [s]; float for a float, array for an array."""
        cfg = self.cfg
        if np.ndim(t) == 0:
            tau = (float(t) - cfg.gust_start_s) / cfg.gust_duration_s if cfg.gust_speed_mps != 0.0 else -1.0
            if 0.0 <= tau <= 1.0:
                return 0.5 * cfg.gust_speed_mps * (1.0 - math.cos(_TWO_PI * tau))
            return 0.0
        t = np.asarray(t, dtype=float)
        if cfg.gust_speed_mps == 0.0:
            return np.zeros_like(t)
        tau = (t - cfg.gust_start_s) / cfg.gust_duration_s
        inside = (tau >= 0.0) & (tau <= 1.0)
        return np.where(inside, 0.5 * cfg.gust_speed_mps * (1.0 - np.cos(_TWO_PI * tau)), 0.0)

    def turbulence(self, t: np.ndarray | float, r: np.ndarray) -> np.ndarray:
        """Turbulent velocity fluctuation (zero mean) at positions ``r``; shapes as in :meth:`velocity`."""
        pos = np.asarray(r, dtype=float)
        out = self._turbulence(t, pos.reshape(-1, 3))
        return out[0] if pos.ndim == 1 else out

    def _turbulence(self, t: np.ndarray | float, pos: np.ndarray) -> np.ndarray:
        """``pos (n, 3)`` -> new ``(n, 3)`` array; the phase of each mode is ``k . r - omega t + theta``."""
        n = pos.shape[0]
        if not self.turbulent:
            return np.zeros((n, 3))
        if self.backend == "numba":
            t_arr = np.asarray(t, dtype=float).reshape(-1)
            if t_arr.shape[0] not in (1, n):
                raise ValueError(f"t must be a float or have one entry per position, got shape {np.shape(t)}")
            out = np.empty((n, 3))
            return _turbulence_kernel(t_arr, np.ascontiguousarray(pos), self.wavevec_t, self.phase0,
                                      self.omega, self.amp, self.cfg.turbulence_modes, out)
        if np.ndim(t) == 0:
            phase_t = np.remainder(self.phase0 - self.omega * float(t), _TWO_PI)  # (3m,)
        else:  # one time per position
            t = np.asarray(t, dtype=float).reshape(-1, 1)
            phase_t = np.remainder(self.phase0[None, :] - t * self.omega[None, :], _TWO_PI)
        phase = pos @ self.wavevec_t  # (n, 3m)
        phase += phase_t
        np.cos(phase, out=phase)
        phase *= self.amp
        return phase.reshape(n, 3, -1).sum(axis=2)

    def velocity(self, t: np.ndarray | float, r: np.ndarray) -> np.ndarray:
        """Wind velocity in W at time ``t`` and positions ``r``.

        Parameters
        ----------
        t : float [s], or (n,) float [s] (one time per position)
        r : (n, 3) or (3,) float [m], positions in W

        Returns
        -------
        (n, 3) or (3,) float [m/s], same shape as ``r``
        """
        pos = np.asarray(r, dtype=float)
        if pos.ndim not in (1, 2) or pos.shape[-1] != 3:
            raise ValueError(f"r must have shape (3,) or (n, 3), got {pos.shape}")
        pos2 = pos.reshape(-1, 3)
        vel = self._turbulence(t, pos2)
        if self.cfg.profile == "uniform":
            vel[:, 0] += self.cfg.speed_mps + self.gust(t)
        else:
            vel[:, 0] += self.mean_speed(pos2[:, 2]) + self.gust(t)
        return vel[0] if pos.ndim == 1 else vel

    __call__ = velocity
