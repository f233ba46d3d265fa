"""MCMC samplers behind one call: adaptive Metropolis-Hastings and emcee's ensemble sampler.

Both take a *batched* log-posterior ``log_prob(X) -> (B,)`` for ``X`` of shape (B, d): emcee runs
with ``vectorize=True`` (all walkers in one call), Metropolis-Hastings runs several independent
chains in lock-step (all chains' proposals in one call), so each step costs one batched
eigen-solution however many chains there are.

Both run until the ArviZ diagnostics meet their targets (R-hat below ``rhat_target`` and ESS at least
``ess_target`` for every parameter) or ``max_steps`` is reached, in which case the result carries a
warning. Burn-in is discarded: for emcee, five integrated autocorrelation times (at least a quarter
of the run); for MH, the adaptation phase, after which the proposal is frozen so the chain that is
kept is a proper (non-adaptive) Markov chain.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .diagnostics import ChainDiagnostics, chain_diagnostics

LogProb = Callable[[np.ndarray], np.ndarray]

MH_TARGET_ACCEPTANCE = 0.25  # inside the 0.15-0.4 band recommended for random-walk proposals
MH_ACCEPTANCE_BAND = (0.15, 0.40)


@dataclass
class SamplerSettings:
    sampler: str = "emcee"  # a name registered in sampler_kinds (built in: "emcee", "mh")
    n_chains: int = 0  # walkers (emcee) or chains (mh); 0 = automatic
    n_steps: int = 1500  # first run length (after which diagnostics decide)
    max_steps: int = 20000
    burn_in: int = 0  # MH adaptation steps; 0 = automatic (n_steps // 2)
    rhat_target: float = 1.01
    ess_target: float = 1000.0
    seed: int = 0
    # called with (steps done, steps planned so far) while sampling: progress and ETA on a terminal
    progress: Callable[[int, int], None] | None = None


def _emcee_steps(sampler: Any, start: Any, steps: int, settings: SamplerSettings) -> Any:
    """``sampler.run_mcmc(start, steps)`` (the same draws), reporting progress every 50 steps."""
    if settings.progress is None:
        return sampler.run_mcmc(start, steps, progress=False)
    target = sampler.iteration + steps
    state = None
    for k, drawn in enumerate(sampler.sample(start, iterations=steps), 1):
        state = drawn
        if k % 50 == 0 or k == steps:
            settings.progress(sampler.iteration, target)
    return state


@dataclass
class ChainResult:
    sampler: str
    chains: np.ndarray  # (n_chains, n_draws, d), burn-in removed
    log_prob: np.ndarray  # (n_chains, n_draws)
    acceptance: float
    burn_in: int
    n_steps: int
    n_evaluations: int
    diagnostics: ChainDiagnostics
    converged: bool
    warnings: list[str] = field(default_factory=list)

    @property
    def flat(self) -> np.ndarray:
        return self.chains.reshape(-1, self.chains.shape[-1])


def find_map(log_prob: LogProb, starts: np.ndarray, scale: np.ndarray, *, batch: int = 96,
             rounds: int = 30, seed: int = 0) -> tuple[np.ndarray, float]:
    """Maximum of the log-posterior using batched evaluations only.

    1. the best of ``starts`` (one batch);
    2. a cross-entropy search: sample ``batch`` points from a Gaussian around the current elite,
       refit it to the best tenth, shrink until the spread is tiny (one batch per round);
    3. Newton refinement with central-difference gradient and Hessian, each iteration one batch
       (stencil and line-search points together).

    Every step is a batch because a likelihood with IIRS reduction costs almost the same for 1 or
    256 parameter vectors; a one-point optimiser (Nelder-Mead) would be ~100 times slower here.
    """
    rng = np.random.default_rng(seed)
    lp = log_prob(starts)
    if not np.isfinite(np.max(lp)):
        raise RuntimeError("the log-posterior is -inf at every starting point; check priors and data")
    order = np.argsort(lp)[::-1]
    n_elite = max(8, batch // 10)
    elite = starts[order[:n_elite]]
    best, best_lp = starts[order[0]].copy(), float(lp[order[0]])
    mean = best.copy()
    cov = np.cov(elite.T).reshape(best.size, best.size) + np.diag((0.05 * scale) ** 2)
    for _ in range(rounds):
        try:
            L = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            L = np.diag(np.sqrt(np.clip(np.diag(cov), 1e-300, None)))
        pts = mean + rng.standard_normal((batch, best.size)) @ L.T
        pts[0] = best
        v = log_prob(pts)
        o = np.argsort(v)[::-1][:n_elite]
        if v[o[0]] > best_lp:
            best, best_lp = pts[o[0]].copy(), float(v[o[0]])
        el = pts[o][np.isfinite(v[o])]
        if el.shape[0] < 2:
            cov *= 0.25
            continue
        mean = el.mean(axis=0)
        cov = 0.7 * np.cov(el.T).reshape(best.size, best.size) + 0.3 * cov * 0.5
        if np.all(np.sqrt(np.diag(cov)) < 3e-3 * scale):  # near the mode: Newton takes over
            break
    return newton_refine(log_prob, best, best_lp, scale)


def _stencil(x0: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, dict]:
    d = x0.size
    pts, idx = [x0.copy()], {}
    for i in range(d):
        for j in range(i, d):
            for si, sj in (((1, 1), (1, -1), (-1, 1), (-1, -1)) if i != j else ((1, 0), (-1, 0))):
                p = x0.copy()
                p[i] += si * h[i]
                if i != j:
                    p[j] += sj * h[j]
                idx[(i, j, si, sj)] = len(pts)
                pts.append(p)
    return np.array(pts), idx


def _grad_hess(f: np.ndarray, idx: dict, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = h.size
    g = np.zeros(d)
    H = np.zeros((d, d))
    for i in range(d):
        fp, fm = f[idx[(i, i, 1, 0)]], f[idx[(i, i, -1, 0)]]
        g[i] = (fp - fm) / (2 * h[i])
        H[i, i] = (fp - 2 * f[0] + fm) / h[i] ** 2
        for j in range(i + 1, d):
            v = (f[idx[(i, j, 1, 1)]] - f[idx[(i, j, 1, -1)]] - f[idx[(i, j, -1, 1)]]
                 + f[idx[(i, j, -1, -1)]]) / (4 * h[i] * h[j])
            H[i, j] = H[j, i] = v
    return g, H


def newton_refine(log_prob: LogProb, x: np.ndarray, lp: float, scale: np.ndarray,
                  iterations: int = 30) -> tuple[np.ndarray, float]:
    """Damped Newton steps on the log-posterior, stencil and line search in one batch each step."""
    alphas = 2.0 ** -np.arange(0, 12)
    h = 1e-3 * scale
    for _ in range(iterations):
        pts, idx = _stencil(x, h)
        f = log_prob(pts)
        if not np.all(np.isfinite(f)):
            h = h * 0.1
            continue
        g, H = _grad_hess(f, idx, h)
        try:
            np.linalg.cholesky(-H)
            step = np.linalg.solve(-H, g)
        except np.linalg.LinAlgError:
            step = g * (scale**2) * 1e-2 / max(np.linalg.norm(g * scale), 1e-300)
        cand = x + alphas[:, None] * step[None]
        v = log_prob(cand)
        k = int(np.argmax(v))
        if not v[k] > lp + 1e-10:
            # shrink the difference step once the Newton step is below it
            if np.all(np.abs(step) < h):
                break
            h = h * 0.3
            continue
        gain = v[k] - lp
        x, lp = cand[k].copy(), float(v[k])
        h = np.clip(np.abs(step) * 0.1, 1e-7 * scale, 1e-3 * scale)
        if gain < 1e-8:
            break
    return x, lp


def laplace_covariance(log_prob: LogProb, x0: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Inverse of minus the Hessian of the log-posterior at ``x0`` (central differences, one batch).

    Falls back to a small diagonal when the Hessian is not negative definite.
    """
    for rel in (1e-3, 1e-4, 1e-2, 1e-5):
        h = rel * scale
        pts, idx = _stencil(x0, h)
        f = log_prob(pts)
        if not np.all(np.isfinite(f)):
            continue
        _, H = _grad_hess(f, idx, h)
        try:
            cov = np.linalg.inv(-H)
            np.linalg.cholesky(cov)
            return 0.5 * (cov + cov.T)
        except np.linalg.LinAlgError:
            continue
    return np.diag((1e-3 * scale) ** 2)


def _counted(log_prob: LogProb) -> tuple[LogProb, list[int]]:
    count = [0]

    def f(x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        count[0] += x.shape[0]
        return np.asarray(log_prob(x), dtype=float)

    return f, count


def _ball(rng: np.random.Generator, center: np.ndarray, cov: np.ndarray, n: int, inflate: float,
          log_prob: LogProb) -> np.ndarray:
    """``n`` starting points around ``center`` drawn from N(center, inflate^2 cov), all finite."""
    L = np.linalg.cholesky(cov)
    out = center + inflate * rng.standard_normal((n, center.size)) @ L.T
    for _ in range(50):
        bad = ~np.isfinite(log_prob(out))
        if not bad.any():
            break
        out[bad] = center + 0.5 * inflate * rng.standard_normal((bad.sum(), center.size)) @ L.T
        inflate *= 0.5
    return out


def run_emcee(log_prob: LogProb, center: np.ndarray, cov: np.ndarray, settings: SamplerSettings,
              names: list[str]) -> ChainResult:
    """emcee's affine-invariant ensemble sampler (vectorised), extended until converged."""
    import emcee

    rng = np.random.default_rng(settings.seed)
    d = center.size
    n_w = settings.n_chains or max(32, 8 * d)
    n_w += n_w % 2
    lp, count = _counted(log_prob)
    p0 = _ball(rng, center, cov, n_w, 1.0, lp)
    # Differential-evolution moves mix about three times faster than the default stretch move on
    # the near-Gaussian posteriors of updating (integrated autocorrelation ~13 vs ~33 steps, d = 3).
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(n_w, d, lp, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(settings.seed).get_state()
    state = _emcee_steps(sampler, p0, settings.n_steps, settings)
    warnings_: list[str] = []
    while True:
        n = sampler.iteration
        tau = np.nan_to_num(sampler.get_autocorr_time(tol=0, quiet=True), nan=n / 4)
        burn = int(min(max(5 * np.max(tau), n // 4), n // 2))
        chains = np.swapaxes(sampler.get_chain()[burn:], 0, 1)
        diag = chain_diagnostics(chains, names)
        if diag.meets(settings.rhat_target, settings.ess_target) or n >= settings.max_steps:
            break
        # extend by the steps the ESS shortfall suggests (at least half the current length)
        need = settings.ess_target / max(diag.ess_min, 1.0) * (n - burn)
        extra = int(min(max(need - (n - burn), n // 2, 100), settings.max_steps - n))
        state = _emcee_steps(sampler, state, extra, settings)
    acc = float(np.mean(sampler.acceptance_fraction))
    diag.acceptance = acc
    converged = diag.meets(settings.rhat_target, settings.ess_target)
    if not converged:
        warnings_.append(f"emcee stopped at {sampler.iteration} steps without meeting R-hat < "
                         f"{settings.rhat_target} and ESS >= {settings.ess_target:.0f} "
                         f"(R-hat max {diag.rhat_max:.4f}, ESS min {diag.ess_min:.0f})")
    if not 0.1 <= acc <= 0.7:
        warnings_.append(f"emcee acceptance fraction {acc:.2f} is unusual (expected 0.2-0.5)")
    lps = np.swapaxes(sampler.get_log_prob()[burn:], 0, 1)
    return ChainResult("emcee", chains, lps, acc, burn, sampler.iteration, count[0], diag, converged,
                       warnings_)


@dataclass
class _Adaptation:
    """Metropolis-Hastings burn-in: the proposal follows the chains' pooled covariance and a global
    scale is tuned by Robbins-Monro steps toward the target acceptance, every ``block`` steps."""

    cov: np.ndarray  # the Laplace covariance (fallback)
    log_s: float
    prop_cov: np.ndarray
    chol: np.ndarray
    hist: list[np.ndarray] = field(default_factory=list)
    acc_hist: list[np.ndarray] = field(default_factory=list)
    block: int = 50

    @staticmethod
    def start(cov: np.ndarray) -> _Adaptation:
        log_s = math.log(2.38**2 / cov.shape[0])
        return _Adaptation(cov, log_s, cov.copy(), np.linalg.cholesky(math.exp(log_s) * cov))

    def observe(self, step: int, x: np.ndarray, accept: np.ndarray) -> None:
        self.hist.append(x.copy())
        self.acc_hist.append(accept)
        if step % self.block:
            return
        rate = float(np.mean(self.acc_hist[-self.block:]))
        self.log_s += 2.0 * (rate - MH_TARGET_ACCEPTANCE) / math.sqrt(step / self.block)
        if step >= 4 * self.block:  # pooled covariance of the recent half of the history
            d = x.shape[1]
            emp = np.cov(np.concatenate(self.hist[len(self.hist) // 2:]).T).reshape(d, d)
            self.prop_cov = emp + 1e-12 * np.diag(np.diag(emp) + 1e-300)
        try:
            self.chol = np.linalg.cholesky(math.exp(self.log_s) * self.prop_cov)
        except np.linalg.LinAlgError:
            self.chol = np.linalg.cholesky(math.exp(self.log_s) * self.cov)


def run_mh(log_prob: LogProb, center: np.ndarray, cov: np.ndarray, settings: SamplerSettings,
           names: list[str]) -> ChainResult:
    """Adaptive random-walk Metropolis-Hastings, several independent chains in lock-step.

    Adaptation (burn-in only, :class:`_Adaptation`): the proposal covariance follows the chains'
    pooled empirical covariance and a global scale is tuned by Robbins-Monro steps toward an
    acceptance rate of 0.25. The proposal is then frozen and the kept part is plain
    Metropolis-Hastings with a symmetric Gaussian proposal (the q terms of the acceptance ratio cancel).
    """
    rng = np.random.default_rng(settings.seed)
    d = center.size
    n_c = settings.n_chains or 8
    lp_fn, count = _counted(log_prob)
    # over-dispersed starts (twice the Laplace spread) so that R-hat can detect non-mixing
    x = _ball(rng, center, cov, n_c, 2.0, lp_fn)
    lp = lp_fn(x)
    burn = settings.burn_in or max(settings.n_steps // 2, 200)
    adapt = _Adaptation.start(cov)
    total, step = burn + settings.n_steps, 0
    kept_x: list[np.ndarray] = []
    kept_lp: list[np.ndarray] = []
    kept_acc: list[np.ndarray] = []
    while True:
        while step < total:
            prop = x + rng.standard_normal((n_c, d)) @ adapt.chol.T
            lp_new = lp_fn(prop)
            accept = (np.log(rng.random(n_c)) < (lp_new - lp)) & np.isfinite(lp_new)
            x = np.where(accept[:, None], prop, x)
            lp = np.where(accept, lp_new, lp)
            step += 1
            if settings.progress is not None and (step % 100 == 0 or step == total):
                settings.progress(step, total)
            if step <= burn:
                adapt.observe(step, x, accept)
            else:
                kept_x.append(x.copy())
                kept_lp.append(lp.copy())
                kept_acc.append(accept)
        chains = np.stack(kept_x, axis=1)
        diag = chain_diagnostics(chains, names)
        if diag.meets(settings.rhat_target, settings.ess_target) or step >= settings.max_steps:
            break
        n_kept = len(kept_x)
        need = settings.ess_target / max(diag.ess_min, 1.0) * n_kept
        total = min(step + int(max(need - n_kept, n_kept // 2, 100)), settings.max_steps)
    acc = float(np.mean(kept_acc))
    return ChainResult("mh", chains, np.stack(kept_lp, axis=1), acc, burn, step, count[0], diag,
                       *_mh_verdict(diag, acc, step, settings))


def _mh_verdict(diag: ChainDiagnostics, acc: float, step: int, settings: SamplerSettings) -> tuple[bool, list[str]]:
    diag.acceptance = acc
    converged = diag.meets(settings.rhat_target, settings.ess_target)
    warnings_: list[str] = []
    if not converged:
        warnings_.append(f"Metropolis-Hastings stopped at {step} steps without meeting R-hat < "
                         f"{settings.rhat_target} and ESS >= {settings.ess_target:.0f} "
                         f"(R-hat max {diag.rhat_max:.4f}, ESS min {diag.ess_min:.0f})")
    lo, hi = MH_ACCEPTANCE_BAND
    if not lo <= acc <= hi:
        warnings_.append(f"Metropolis-Hastings acceptance {acc:.2f} outside [{lo}, {hi}]")
    return converged, warnings_
