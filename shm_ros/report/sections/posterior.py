"""Posterior (update): parameter table, sampler diagnostics and evidence, corner and trace plots."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import write_csv

#: draws written next to the corner/trace plots (thinned evenly, all chains)
MAX_DRAWS = 4000


def _prior_text(p: dict[str, Any] | None) -> str:
    if not p:
        return "–"
    rest = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in p.items() if k != "dist")
    return f"{p.get('dist', '?')}({rest})"


class PosteriorSection:
    key = "posterior"
    title = "Posterior (model updating)"
    order = 40

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        post = inputs.posterior
        if post is None:
            return None
        d = post.diagnostics
        s = Section(self.key, self.title)
        s.paragraphs.append(
            f"{len(post.parameter_names)} parameters ({', '.join(post.parameter_names)}) updated on "
            f"{d.get('n_windows', '?')} windows with the {d.get('likelihood', '?')} likelihood and the "
            f"{d.get('sampler', '?')} sampler; " + ("converged." if d.get("converged") else
                                                    "the convergence targets were NOT reached."))
        s.notes += list(post.warnings)
        rhat, ess = d.get("rhat", {}), d.get("ess_bulk", {})
        cols = ["parameter", "prior", "MAP", "mean", "std", "95 % low", "95 % high", "R-hat", "ESS (bulk)"]
        rows = [[n, _prior_text(post.priors.get(n)), p.map, p.mean, p.std, p.ci95[0], p.ci95[1],
                 rhat.get(n), ess.get(n)] for n, p in post.parameters.items()]
        data = write_csv(fig_dir / "posterior_parameters.csv", cols, rows)
        s.tables.append(Table(cols, rows, "Parameters (95 % equal-tailed interval)", data))
        s.tables.append(Table(["diagnostic", "value"], self._diagnostics(post), "Sampler diagnostics and evidence"))
        s.figures += self._plots(post, fig_dir)
        return s

    @staticmethod
    def _diagnostics(post: Any) -> list[list[Any]]:
        d, fit, nom = post.diagnostics, post.fit or {}, post.fit_nominal or {}
        ev = "not computed" if post.log_evidence is None else (
            f"{post.log_evidence:.3f}" + ("" if post.log_evidence_err is None else f" ± {post.log_evidence_err:.3f}")
            + (f" ({d['evidence_method']})" if d.get("evidence_method") else ""))
        rows: list[list[Any]] = [
            ["sampler", str(d.get("sampler", ""))],
            ["likelihood", str(d.get("likelihood", ""))],
            ["chains × draws (kept)", f"{d.get('n_chains', '?')} × {d.get('n_draws', '?')}"],
            ["burn-in / steps", f"{d.get('burn_in', '?')} / {d.get('n_steps', '?')}"],
            ["R-hat (max)", d.get("rhat_max")],
            ["ESS (min, bulk)", d.get("ess_min")],
            ["acceptance", d.get("acceptance")],
            ["converged", bool(d.get("converged", False))],
            ["log evidence", ev],
        ]
        if fit.get("frequency_rmse_pct") is not None:
            rows.append(["frequency RMSE at MAP / nominal (%)",
                         f"{fit['frequency_rmse_pct']:.3g} / {nom.get('frequency_rmse_pct', float('nan')):.3g}"])
        if fit.get("mac_mean") is not None:
            rows.append(["mean MAC at MAP", fit["mac_mean"]])
        return rows

    @staticmethod
    def _plots(post: Any, fig_dir: Path) -> list[Figure]:
        from shm_ros.report.posterior import posterior_plots

        chains = np.asarray(post.chains, float)
        if chains.ndim != 3 or chains.shape[1] < 2:
            return []
        n_c, n_d, _ = chains.shape
        lp = np.asarray(post.log_prob, float).reshape(n_c, n_d)
        names = list(post.chain_names)
        out_dir = fig_dir / "posterior"
        paths = posterior_plots(chains, lp, names, out_dir)
        thin = max(1, (n_c * n_d) // MAX_DRAWS)
        rows = [[c, k, *chains[c, k], lp[c, k]] for c in range(n_c) for k in range(0, n_d, thin)]
        header = ["chain", "draw", *names, "log_posterior"]
        figs = []
        for kind, caption in (("corner", "Pairwise posterior of the parameters (marginals on the diagonal)."),
                              ("trace", "Trace of every chain (left: density per chain; right: draws).")):
            if kind in paths:
                data = write_csv(out_dir / f"{kind}.csv", header, rows)
                figs.append(Figure(Path(paths[kind]), data, caption))
        return figs


BUILDER = PosteriorSection()
