"""The files of one updating run: ``posterior.json`` (strict JSON with schema and provenance) and
``samples.npz`` (draws, log posterior, chains), written alike by ``shm-ros update`` and the update
node; ``shm_ros.report.load.load_posterior`` reads them back."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.provenance import stamp_output
from shm_ros.io import jsonio


def write_posterior(out_dir: str | Path, post: Any, config: dict[str, Any], seed: int | None = None
                    ) -> tuple[Path, Path]:
    """Write ``posterior.json`` and ``samples.npz`` of ``post`` (a ``Posterior``) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = jsonio.dump(stamp_output(post.to_dict(), config, seed), out / "posterior.json", indent=2)
    samples = out / "samples.npz"
    # write then rename: a reader never sees a half-written file of a run that is rewritten
    tmp = out / ".samples.tmp.npz"
    np.savez_compressed(tmp, samples=post.samples, log_prob=post.log_prob, chains=post.chains,
                        chain_names=np.array(post.chain_names), parameter_names=np.array(post.parameter_names))
    tmp.replace(samples)
    return doc, samples
