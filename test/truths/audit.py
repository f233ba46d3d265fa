"""Effect size against nuisance, from the recordings: ``python -m truths.audit [--seeds N] [--size S]``
(run from ``test/``).

For each event kind and seed, the campaign and the clean campaign of the same seed (same building,
same ground motions) are read back through the project's bag reader; per event, the apparent first
frequency and damping ratio (lowest mode of an ARX model of order 2 n + 4, ground to top floor, over the
strong-motion phase) are compared. Scatter: the standard deviation over the clean campaign's events
of the apparent frequency relative to the truth's small-amplitude frequency (nuisance +
estimation), and of log damping around its mean. Effect: the largest change from the clean
campaign over the events.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from .apparent import arx_mode, strong_part
from .event_effects import EFFECTS
from .registry import make_campaign


def apparent(campaign) -> tuple[np.ndarray, np.ndarray, dict]:
    from shm_ros.io.recording import windows_from_bag

    truth = json.loads(campaign.truth.read_text())
    windows, _ = windows_from_bag(campaign.data, campaign.structure)
    top = truth["channels"][-1]
    order = 2 * truth["building"]["stories"] + 4   # x, y and torsion of each floor show in an x sensor
    fh = []
    for w in windows:
        g, y = w.samples[:, w.channel_names.index("g0")], w.samples[:, w.channel_names.index(top)]
        part = strong_part(g, w.sample_rate_hz)
        fh.append(arx_mode(g[part], y[part], w.sample_rate_hz, order))
    fh = np.array(fh)
    return fh[:, 0], fh[:, 1], truth


def audit(seeds: int, size: str, out: Path) -> list[dict]:
    rows = []
    for seed in range(seeds):
        f0, h0, t0 = apparent(make_campaign("event_clean", seed, size, out / f"clean-{seed}"))
        f_small = np.array([e["small_amplitude_frequencies_hz"][0] for e in t0["events"]])
        ratio = f0 / f_small
        scatter_f = float(np.std(ratio / ratio.mean() - 1, ddof=1))
        scatter_h = float(np.std(np.log(h0), ddof=1))
        for kind in EFFECTS:
            if kind == "event_clean":
                continue
            f1, h1, _ = apparent(make_campaign(kind, seed, size, out / f"{kind}-{seed}"))
            df = float(np.max(np.abs(f1 / f0 - 1)))
            dh = float(np.max(np.abs(np.log(h1 / h0))))
            rows.append({"kind": kind, "seed": seed, "freq_change": df, "freq_scatter": scatter_f,
                         "log_damping_change": dh, "log_damping_scatter": scatter_h,
                         "ratio": max(df / scatter_f, dh / scatter_h)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--size", default="reduced", choices=["reduced", "full"])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = audit(args.seeds, args.size, Path(tmp))
    print(f"{'kind':28s} seed  df/f    scatter  dln(zeta) scatter  effect/scatter")
    for r in rows:
        print(f"{r['kind']:28s} {r['seed']:4d}  {r['freq_change']:.4f}  {r['freq_scatter']:.4f}   "
              f"{r['log_damping_change']:.3f}  {r['log_damping_scatter']:.3f}    {r['ratio']:.1f}")


if __name__ == "__main__":
    main()
