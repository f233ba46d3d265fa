"""The worked example of docs/explain.md is one command (examples/explain_example.sh): it runs as a
user runs it (simulate, explain on the table, the figures), here on a shorter campaign (96 windows,
16 hours) to keep CI short. Its content is checked against the simulated truth (a deck that stiffens
as it cools, -0.2 %/degC above a 2 degC knee and -4.2 %/degC below): the named effect has that sign,
it removes most of the frequency misfit, it clears the threshold, and the figures are not blank."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_worked_example_runs_with_one_command(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "OPENBLAS_NUM_THREADS": "1"}
    out = tmp_path / "example"
    run = subprocess.run(["bash", str(ROOT / "examples" / "explain_example.sh"), str(out), "96"], env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    verdict = json.loads((out / "explain" / "verdict.json").read_text())
    assert verdict["missing_physics"][0]["name"] == "temperature_dependent_stiffness", verdict["missing_physics"]
    assert "frequency RMSE" in run.stdout and "misfit left" in run.stdout, run.stdout
    top = verdict["missing_physics"][0]
    slopes = {k: v for k, v in top["parameters"].items() if k.endswith("_per_c")}
    assert slopes and all(v < 0 for v in slopes.values()), top  # colder deck, stiffer deck
    assert any(top["intervals"][k][1] < 0 for k in slopes), top["intervals"]  # the effect is resolved
    assert top["log_evidence_gain"] > verdict["threshold"]["log_bayes_factor"]
    before, after = (verdict["fit"][k]["frequency_rmse_pct"] for k in ("before", "after"))
    assert after < 0.5 * before, (before, after)
    from matplotlib.image import imread

    # drawn, not empty (the candidates' chart has one bar per candidate: on 96 windows locate, reading the
    # training windows only, may propose one)
    for name, size in (("data", 10_000), ("form", 10_000), ("candidates", 4_000)):
        png = out / "explain" / f"explain_example_{name}.png"
        assert png.stat().st_size > size
        img = imread(png)
        assert img.shape[1] > 200 and img.shape[0] > 100 and img[..., :3].std() > 0.05, (name, img.shape)  # drawn
