"""Plots of a posterior: pairwise (corner) plot and trace plot, through ArviZ on matplotlib (Agg)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from shm_ros.core.bayes.diagnostics import inference_data


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def posterior_plots(chains: np.ndarray, log_prob: np.ndarray, names: list[str], out_dir: str | Path,
                    truth: dict[str, float] | None = None, max_draws: int = 4000) -> dict[str, str]:
    """Write ``corner.png`` and ``trace.png`` into ``out_dir``; returns {kind: path}.

    ``chains`` (n_chains, n_draws, d); long runs are thinned to about ``max_draws`` draws per plot.
    """
    plt = _pyplot()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import arviz as az

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n_c, n_d, _ = chains.shape
    thin = max(1, (n_c * n_d) // max_draws)
    idata = inference_data(chains[:, ::thin], log_prob[:, ::thin], names)
    paths = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        axes = az.plot_pair(idata, var_names=names, kind="scatter", marginals=True,
                            scatter_kwargs={"alpha": 0.15, "s": 2},
                            reference_values=truth or None,
                            figsize=(2.6 * len(names) + 1, 2.6 * len(names) + 1))
        fig = np.ravel(axes)[0].get_figure()
        fig.suptitle("posterior (pairwise)")
        paths["corner"] = str(out_dir / "corner.png")
        fig.savefig(paths["corner"], dpi=90, bbox_inches="tight")
        plt.close(fig)
        axes = az.plot_trace(idata, var_names=names, compact=False,
                             figsize=(10, 2.4 * len(names) + 1))
        fig = np.ravel(axes)[0].get_figure()
        fig.tight_layout()
        paths["trace"] = str(out_dir / "trace.png")
        fig.savefig(paths["trace"], dpi=80, bbox_inches="tight")
        plt.close(fig)
    return paths
