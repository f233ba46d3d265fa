"""Test-side generator of synthetic acceleration records that SSI does NOT assume.

Deliberately finer and messier than the identified model:

* a chain (shear-type) structure with many more DOFs than identified modes, non-uniform masses and
  stiffnesses, Rayleigh damping *plus* discrete story dashpots (non-proportional damping: complex
  modes);
* exact integration of each complex mode for a force held over a fine step (8x the output rate),
  then decimation with a polyphase FIR anti-alias filter (``scipy.signal.resample_poly``);
* coloured (band-limited, peaked) and non-stationary (slowly amplitude-modulated) excitation at all
  DOFs plus a spatially coherent gust component; direct force feed-through into the accelerations;
* per-channel Gaussian sensor noise at a given fraction of that channel's RMS, static offsets
  (gravity on some channels, sensor bias) and slow drift.

Truth modes come from the complex eigenproblem of the full model.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig


@dataclass
class Chain:
    M: np.ndarray
    K: np.ndarray
    C: np.ndarray
    floor_dofs: np.ndarray  # DOF index of each "floor" (sensor candidates), bottom up


@dataclass
class Truth:
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray  # (n_modes, n_sensors) complex displacement shapes at the sensors


def chain(masses, stiffnesses, zetas=(0.02, 0.02), fit_modes=(0, 3), dashpots=(),
          floor_dofs=None) -> Chain:
    """Fixed-base chain: ``stiffnesses[k]`` connects DOF k to DOF k-1 (the ground for k = 0)."""
    m = np.asarray(masses, float)
    k = np.asarray(stiffnesses, float)
    n = m.size
    K = np.zeros((n, n))
    for j in range(n):
        K[j, j] += k[j]
        if j > 0:
            K[j - 1, j - 1] += k[j]
            K[j - 1, j] -= k[j]
            K[j, j - 1] -= k[j]
    M = np.diag(m)
    w = np.sqrt(sla.eigh(K, M, eigvals_only=True))
    wa, wb = w[fit_modes[0]], w[fit_modes[1]]
    za, zb = zetas
    # Rayleigh: zeta = a/(2w) + b w/2 at the two fitted modes
    mat = np.array([[1 / (2 * wa), wa / 2], [1 / (2 * wb), wb / 2]])
    a, b = np.linalg.solve(mat, [za, zb])
    C = a * M + b * K
    for story, c in dashpots:
        C[story, story] += c
        if story > 0:
            C[story - 1, story - 1] += c
            C[story - 1, story] -= c
            C[story, story - 1] -= c
    fd = np.arange(n) if floor_dofs is None else np.asarray(floor_dofs)
    return Chain(M, K, C, fd)


def tall_building(rng: np.random.Generator, n_floors: int = 12, sub: int = 3) -> Chain:
    """A 12-floor building modelled with ``sub`` DOFs per story (light column nodes between
    floors), non-uniform floors, Rayleigh damping ~2-2.5 % plus two story dashpots."""
    masses, stiff, floors = [], [], []
    for f in range(n_floors):
        mf = 4.0e5 * (1.0 - 0.25 * f / n_floors) * (1 + 0.05 * rng.uniform(-1, 1))
        kf = 6.4e9 * (1.0 - 0.45 * f / n_floors) * (1 + 0.05 * rng.uniform(-1, 1))
        for s in range(sub):
            masses.append(mf if s == sub - 1 else 0.03 * mf)
            stiff.append(kf * sub)
        floors.append(len(masses) - 1)
    n = len(masses)
    cst = 2.0e6
    return chain(masses, stiff, zetas=(0.025, 0.025), fit_modes=(0, 3),
                 dashpots=[(floors[1], cst), (floors[6], 0.5 * cst)], floor_dofs=floors)


def truth_modes(ch: Chain, sensors: np.ndarray, n_modes: int) -> Truth:
    n = ch.M.shape[0]
    minv = np.linalg.inv(ch.M)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ ch.K, -minv @ ch.C]])
    lam, v = sla.eig(a)
    keep = lam.imag > 0
    lam, v = lam[keep], v[:, keep]
    o = np.argsort(np.abs(lam))[:n_modes]
    lam, v = lam[o], v[:, o]
    shapes = v[np.asarray(ch.floor_dofs)[sensors]].T
    shapes = shapes / np.linalg.norm(shapes, axis=1, keepdims=True)
    return Truth(np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam), shapes)


def _modal_response(ch: Chain, force: np.ndarray, dt: float, out_dofs: np.ndarray,
                    base_accel: np.ndarray | None = None) -> np.ndarray:
    """Absolute accelerations at ``out_dofs`` for nodal forces ``force`` (n_t, n) held over each
    step (exact per complex mode), plus the ground acceleration when ``base_accel`` is given."""
    n = ch.M.shape[0]
    minv = np.linalg.inv(ch.M)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ ch.K, -minv @ ch.C]])
    lam, v = sla.eig(a)
    keep = lam.imag > 0  # one of each conjugate pair; state = 2 Re(sum v_k eta_k)
    vinv = np.linalg.inv(v)
    lam_k, v_k, vinv_k = lam[keep], v[:, keep], vinv[keep]
    # modal input: eta_k' = lam_k eta_k + vinv_k[:, n:] M^-1 f
    bk = vinv_k[:, n:] @ minv  # (modes, n)
    p = force @ bk.T  # (n_t, modes) complex
    e = np.exp(lam_k * dt)
    g = (e - 1) / lam_k
    eta = np.empty_like(p)
    for j in range(lam_k.size):
        eta[:, j] = sig.lfilter([0.0, g[j]], [1.0, -e[j]], p[:, j])
    z = 2.0 * (eta @ v_k.T).real  # (n_t, 2n) relative displacement and velocity
    acc_rel = -(z[:, :n] @ (minv @ ch.K).T + z[:, n:] @ (minv @ ch.C).T) + force @ minv.T
    acc = acc_rel[:, out_dofs]
    if base_accel is not None:
        acc = acc + base_accel[:, None]
    return acc


def coloured_force(rng, n_t: int, fs: float, n_dof: int, duration: float) -> np.ndarray:
    """Non-stationary, coloured nodal forces: independent noise at each DOF plus a coherent gust."""
    sos = sig.butter(2, [0.3, 25.0], btype="bandpass", fs=fs, output="sos")
    tilt = sig.butter(1, 6.0, btype="lowpass", fs=fs, output="sos")
    w = rng.standard_normal((n_t, n_dof))
    f = sig.sosfilt(sos, w, axis=0) + 1.5 * sig.sosfilt(tilt, w, axis=0)
    gust = sig.sosfilt(sos, rng.standard_normal(n_t))
    profile = np.linspace(0.3, 1.0, n_dof)
    t = np.arange(n_t) / fs
    env = (1.0 + 0.3 * np.sin(2 * np.pi * t / rng.uniform(150, 400) + rng.uniform(0, 6.3))
           + 0.1 * np.sin(2 * np.pi * t / rng.uniform(40, 90) + rng.uniform(0, 6.3)))
    return (f + 0.2 * gust[:, None] * profile[None, :]) * env[:, None] * 1.0e3


@functools.lru_cache(maxsize=128)
def ambient_record(seed: int, duration: float = 600.0, fs: float = 40.0, noise: float = 0.02,
                   n_sensors: int = 6, oversample: int = 8):
    """(samples (n, n_sensors), fs, Truth, sensor names) of a 12-floor building in ambient
    vibration; Truth holds every mode below 0.45 fs. Cached: tests share records."""
    rng = np.random.default_rng(seed)
    ch = tall_building(rng)
    n_floors = ch.floor_dofs.size
    first = 2 if n_sensors <= n_floors - 2 else 0
    sensors = np.unique(np.round(np.linspace(first, n_floors - 1, n_sensors)).astype(int))
    fs_fine = fs * oversample
    n_out = int(round(duration * fs))
    n_t = n_out * oversample + 400
    force = coloured_force(rng, n_t, fs_fine, ch.M.shape[0], duration)
    acc = _modal_response(ch, force, 1.0 / fs_fine, ch.floor_dofs[sensors])
    acc = sig.resample_poly(acc, 1, oversample, axis=0)[25:25 + n_out]
    samples = _sensor_effects(rng, acc, fs, noise)
    truth = truth_modes(ch, sensors, 12)
    keep = truth.frequency_hz < 0.45 * fs
    truth = Truth(truth.frequency_hz[keep], truth.damping_ratio[keep], truth.shapes[keep])
    samples.flags.writeable = False
    return samples, fs, truth, [f"f{s + 1}" for s in sensors]


def _sensor_effects(rng, acc: np.ndarray, fs: float, noise: float) -> np.ndarray:
    n, l = acc.shape
    rms = acc.std(axis=0)
    out = acc + rng.standard_normal((n, l)) * (noise * rms)[None, :]
    t = np.arange(n) / fs
    offsets = rng.normal(0, 0.05, l)
    offsets[rng.uniform(size=l) < 0.3] += 9.81  # sensors mounted with gravity on this axis
    drift = (rms * rng.uniform(0.5, 2.0, l))[None, :] * np.sin(
        2 * np.pi * t[:, None] / rng.uniform(1500, 4000, l)[None, :] + rng.uniform(0, 6.3, l))
    return out + offsets[None, :] + drift


def kanai_tajimi(rng, duration: float, fs: float, pga: float = 1.0) -> np.ndarray:
    """Enveloped Kanai-Tajimi ground acceleration (fg = 2.5 Hz, zeta_g = 0.6), fine-sampled."""
    wg, zg = 2 * np.pi * 2.5, 0.6
    b, a = sig.bilinear([2 * zg * wg, wg ** 2], [1, 2 * zg * wg, wg ** 2], fs=fs)
    n = int(round(duration * fs))
    x = sig.lfilter(b, a, rng.standard_normal(n))
    t = np.arange(n) / fs
    t1, t2 = 4.0, 0.5 * duration
    env = np.where(t < t1, (t / t1) ** 2, np.where(t < t2, 1.0, np.exp(-0.25 * (t - t2))))
    x = x * env
    return x * pga / np.abs(x).max()


def earthquake_record(seed: int, duration: float = 40.0, fs: float = 100.0, noise: float = 0.02,
                      oversample: int = 8):
    """8-story building (3 DOFs per story) under enveloped Kanai-Tajimi base motion.

    Returns (outputs (n, 8) absolute floor accelerations, input (n,) floor-0 acceleration, fs,
    Truth of the first three modes)."""
    rng = np.random.default_rng(seed)
    masses, stiff, floors = [], [], []
    for f in range(8):
        mf = 5.0e5 * (1.0 - 0.2 * f / 8)
        kf = 8.0e8 * (1.0 - 0.4 * f / 8)
        for s in range(3):
            masses.append(mf if s == 2 else 0.03 * mf)
            stiff.append(3 * kf)
        floors.append(len(masses) - 1)
    ch = chain(masses, stiff, zetas=(0.03, 0.03), fit_modes=(0, 2),
               dashpots=[(floors[0], 3.0e6), (floors[4], 1.5e6)], floor_dofs=floors)
    fs_fine = fs * oversample
    ug = kanai_tajimi(rng, duration + 2.0, fs_fine, pga=rng.uniform(0.3, 2.0))
    n = ch.M.shape[0]
    force = -ug[:, None] * np.diag(ch.M)[None, :]
    # unmeasured ambient forcing (wind, occupants) on top of the measured base motion
    amb = coloured_force(rng, ug.size, fs_fine, n, duration)
    amb *= 0.1 * np.abs(force).std() / amb.std()
    acc = _modal_response(ch, force + amb, 1.0 / fs_fine, ch.floor_dofs, base_accel=ug)
    n_out = int(round(duration * fs))
    acc = sig.resample_poly(acc, 1, oversample, axis=0)[:n_out]
    u = sig.resample_poly(ug, 1, oversample)[:n_out]
    acc = acc + rng.standard_normal(acc.shape) * noise * acc.std(axis=0)
    u = u + rng.standard_normal(u.shape) * noise * u.std()
    acc = acc + rng.normal(0, 0.02, 8)[None, :]  # sensor offsets
    return acc, u, fs, truth_modes(ch, np.arange(8), 3)


def white_noise_record(seed: int, duration: float = 600.0, fs: float = 25.0, n_channels: int = 6):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((int(duration * fs), n_channels)), fs


def match_modes(truth: Truth, freqs: np.ndarray, tol: float = 0.05):
    """For each truth mode, the index of the nearest identified mode within ``tol`` (or -1)."""
    out = []
    for f in truth.frequency_hz:
        if freqs.size == 0:
            out.append(-1)
            continue
        rel = np.abs(freqs - f) / f
        j = int(np.argmin(rel))
        out.append(j if rel[j] <= tol else -1)
    return np.array(out)


def mac_real(truth_shape: np.ndarray, real_shape: np.ndarray) -> float:
    num = np.abs(np.vdot(truth_shape, real_shape)) ** 2
    return float(num / (np.vdot(truth_shape, truth_shape).real * np.dot(real_shape, real_shape)))


def single_blas_thread():
    """Context limiting BLAS to one thread: on a shared 2-core machine, multi-threaded OpenBLAS
    spin-waits make small SVD/eig calls tens of times slower."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")
