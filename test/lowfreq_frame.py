"""Test-side truth: a flexible five-storey frame, first mode near 0.53 Hz, shaken at the top floor.

Outside the analysis model's class on purpose:

* a plane moment frame (two columns and one beam per storey, Euler-Bernoulli elements, joint
  rotations condensed out): its stiffness matrix couples every floor with every other, so it is
  not the tridiagonal matrix of the shear building the structure file describes;
* non-classical damping: Rayleigh damping plus a viscous brace in the first storey and a dashpot
  between the top floor and the ground-fixed shaker frame (complex modes);
* input: the force of a shaker on the top floor (band-limited random, its spectrum not flat),
  measured by a load cell, plus unmeasured wind on every floor; outputs: the absolute
  accelerations of the five floors with sensor noise of a given fraction of each channel's RMS
  and a static offset.

The record is simulated exactly (complex modal superposition with first-order hold,
:func:`shm_ros.core.simulate.linear.from_state_space`); the truth modes are the eigenvalues of the
full first-order matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig

from shm_ros.core.simulate.linear import from_state_space
from shm_ros.core.types import Window

N_FLOORS = 5
SENSORS = [f"a{k}" for k in range(1, N_FLOORS + 1)]
FORCE = "f5"


@dataclass
class FrameCase:
    window: Window
    frequency_hz: np.ndarray  # true modes, ascending
    damping_ratio: np.ndarray
    nominal_mass: np.ndarray  # shear-building description of the structure file
    nominal_stiffness: np.ndarray


def _frame_stiffness(ei_col: np.ndarray, ei_beam: np.ndarray, h: float, span: float) -> np.ndarray:
    """Lateral stiffness of a plane frame, floors 1..n (joint rotations condensed statically)."""
    n = ei_col.size
    k = np.zeros((2 * n, 2 * n))  # DOFs: u_1..u_n, theta_1..theta_n

    def add(dofs: list[int | None], ke: np.ndarray) -> None:
        for a, da in enumerate(dofs):
            for b, db in enumerate(dofs):
                if da is not None and db is not None:
                    k[da, db] += ke[a, b]

    for j in range(n):
        c = 2 * ei_col[j] / h**3  # two columns
        ke = c * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                           [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
        below: list[int | None] = [None, None] if j == 0 else [j - 1, n + j - 1]
        add([*below, j, n + j], ke)
        # the beam bends in double curvature under sway: 6 EI / L at each of its two joints
        k[n + j, n + j] += 2 * 6 * ei_beam[j] / span
    kuu, kut, ktt = k[:n, :n], k[:n, n:], k[n:, n:]
    return kuu - kut @ np.linalg.solve(ktt, kut.T)


def frame_case(seed: int, duration_s: float = 420.0, fs: float = 100.0, f1_hz: float = 0.53,
               noise: float = 0.03, wind: float = 0.3) -> FrameCase:
    rng = np.random.default_rng(seed)
    n = N_FLOORS
    mass = 2.0e4 * (1 + 0.05 * rng.standard_normal(n))
    mass[-1] *= 0.8  # roof
    ei_col = 4.0e7 * np.linspace(1.3, 0.8, n) * (1 + 0.05 * rng.standard_normal(n))
    ei_beam = 6.0e7 * (1 + 0.05 * rng.standard_normal(n))
    kk = _frame_stiffness(ei_col, ei_beam, h=3.5, span=6.0)
    m = np.diag(mass)
    w1 = np.sqrt(sla.eigh(kk, m, eigvals_only=True)[0])
    target = f1_hz * (1 + 0.04 * rng.uniform(-1, 1))
    kk *= (2 * np.pi * target / w1) ** 2
    w = np.sqrt(sla.eigh(kk, m, eigvals_only=True))
    # Rayleigh 1.2 % at modes 1 and 3, a brace dashpot in storey 1, a dashpot at the roof
    za, zb = 0.012, 0.012
    a1 = 2 * (zb * w[2] - za * w[0]) / (w[2] ** 2 - w[0] ** 2)
    a0 = 2 * za * w[0] - a1 * w[0] ** 2
    cc = a0 * m + a1 * kk
    brace = 0.01 * 2 * mass.sum() * w[0]
    cc[0, 0] += brace
    cc[n - 1, n - 1] += 0.004 * 2 * mass.sum() * w[0]
    minv = np.linalg.inv(m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ kk, -minv @ cc]])
    b = np.vstack([np.zeros((n, n)), minv])  # a force on every floor (shaker on the last one)
    c_acc = np.hstack([-minv @ kk, -minv @ cc])
    lam = sla.eigvals(a)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    sysm = from_state_space(a, b, c_acc, minv, Cdisp=np.hstack([np.eye(n), np.zeros((n, n))]))

    nt = int(round(duration_s * fs))
    # shaker: band-limited random force 0.2-8 Hz with a slowly varying amplitude
    sos = sig.butter(4, [0.2, 8.0], btype="bandpass", fs=fs, output="sos")
    shaker = sig.sosfilt(sos, rng.standard_normal(nt + 2000))[2000:]
    shaker *= 1 + 0.3 * np.sin(2 * np.pi * np.arange(nt) / fs / 97.0 + rng.uniform(0, 6))
    shaker *= 500.0 / shaker.std()
    # wind: low-passed random forces on every floor, partly coherent
    sos_w = sig.butter(2, 3.0, fs=fs, output="sos")
    common = sig.sosfilt(sos_w, rng.standard_normal(nt + 2000))[2000:]
    local = sig.sosfilt(sos_w, rng.standard_normal((nt + 2000, n)), axis=0)[2000:]
    gust = common[:, None] * np.linspace(0.5, 1.0, n) + local
    gust *= wind * 500.0 / gust.std()
    u = gust.copy()
    u[:, -1] += shaker
    y = sysm.simulate(u, 1.0 / fs)
    y += noise * y.std(axis=0) * rng.standard_normal(y.shape) + rng.normal(0, 0.05, n)
    f_meas = shaker + 0.01 * shaker.std() * rng.standard_normal(nt)
    samples = np.column_stack([y, f_meas])
    win = Window(f"frame{seed}", 0, fs, [*SENSORS, FORCE], samples, input_channel=FORCE)
    # the structure file's shear building: floor masses and storey stiffnesses that give the
    # frame's first modes roughly (a nominal model is never exact)
    k_story = _story_stiffness_fit(kk)
    return FrameCase(win, np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam), mass * 1.03, k_story)


def _story_stiffness_fit(kk: np.ndarray) -> np.ndarray:
    """Storey stiffnesses of a shear building with the frame's lateral stiffness under a
    triangular load (what a designer's simple model would use)."""
    n = kk.shape[0]
    load = np.arange(1, n + 1, dtype=float)
    u = np.linalg.solve(kk, load)
    drift = np.diff(np.concatenate([[0.0], u]))
    shear = np.cumsum(load[::-1])[::-1]
    return shear / drift


def structure_dict(case: FrameCase, with_input: bool = True) -> dict:
    """A structure file (docs/interfaces.md §2) for the frame as a shear building."""
    floors = [{"mass": float(mm), "stiffness": float(k)}
              for mm, k in zip(case.nominal_mass, case.nominal_stiffness, strict=True)]
    sensors = [{"id": s, "at": {"floor": k + 1}, "direction": "x"} for k, s in enumerate(SENSORS)]
    d: dict = {"name": "frame", "kind": "shear_building", "shear_building": {"floors": floors},
               "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]}, "sensors": sensors}
    if with_input:
        d["sensors"].append({"id": FORCE, "at": {"floor": N_FLOORS}, "direction": "x"})
        d["input"] = {"sensor": FORCE, "kind": "force", "at": {"floor": N_FLOORS}, "gain": 1.0}
    return d
