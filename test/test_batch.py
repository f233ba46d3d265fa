"""`shm-ros batch`: an archive of many bags of two structures re-processed on a 2-worker local Dask
cluster gives the serial results (apart from provenance)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

N_BAGS_A, N_BAGS_B = 12, 8  # 20 bags
CONFIG = {"window_s": 60.0, "track": {"reference_windows": 6},
          "update": {"n_steps": 300, "max_steps": 300, "evidence": False, "seed": 3}}


def _campaign(folder: Path, seed: int, day: int) -> None:
    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import write_campaign

    sc = named_scenario("girder")
    sc.n_windows, sc.window_s, sc.seed = 2, 60.0, seed
    sc.start = f"2024-03-{1 + day:02d}T00:00:00Z"
    write_campaign(simulate_campaign(sc), folder)


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("archive")
    for site, n, seed0 in (("site_a", N_BAGS_A, 100), ("site_b", N_BAGS_B, 200)):
        for k in range(n):
            _campaign(root / site / f"day_{k:02d}", seed0 + k, k)
        # one structure file per site, next to its bags; site B has nothing to update
        spec = yaml.safe_load((root / site / "day_00" / "structure.yaml").read_text())
        spec["name"] = site
        if site == "site_b":
            spec.pop("parameters", None)
        (root / site / "structure.yaml").write_text(yaml.safe_dump(spec))
        for k in range(n):
            (root / site / f"day_{k:02d}" / "structure.yaml").unlink()
    (root / "batch.yaml").write_text(yaml.safe_dump(CONFIG))
    return root


def _batch(archive: Path, out: Path, *engine: str) -> subprocess.CompletedProcess:
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "batch", str(archive / "site_a"),
                          str(archive / "site_b"), "--out", str(out), "--config", str(archive / "batch.yaml"),
                          *engine], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return run


def _strip(doc):
    """Provenance and run times differ between any two runs; everything else must not."""
    if isinstance(doc, dict):
        return {k: _strip(v) for k, v in doc.items() if k not in ("provenance", "timing_s")}
    if isinstance(doc, list):
        return [_strip(v) for v in doc]
    return doc


def _without_provenance(path: Path):
    if path.suffix == ".json":
        return _strip(json.loads(path.read_text()))
    return path.read_text()


def test_dask_batch_equals_serial(archive, tmp_path):
    dask_run = _batch(archive, tmp_path / "dask", "--engine", "dask", "--workers", "2")
    _batch(archive, tmp_path / "serial", "--engine", "serial")
    assert "ETA" in dask_run.stdout  # progress is shown
    files = sorted(p.relative_to(tmp_path / "serial") for p in (tmp_path / "serial").rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(tmp_path / "dask") for p in (tmp_path / "dask").rglob("*") if p.is_file())
    names = {str(f) for f in files}
    assert {"site_a/modes.json", "site_a/tracked_modes.csv", "site_a/posterior.json",
            "site_b/modes.json", "site_b/tracked_modes.csv", "batch.json"} <= names
    assert "site_b/posterior.json" not in names  # no parameters: no update
    for f in files:
        assert _without_provenance(tmp_path / "serial" / f) == _without_provenance(tmp_path / "dask" / f), f
    summary = json.loads((tmp_path / "dask" / "batch.json").read_text())
    assert len(summary["bags"]) == N_BAGS_A + N_BAGS_B
    assert all(b["identified"] == 2 and not b["errors"] for b in summary["bags"])
    modes = json.loads((tmp_path / "dask" / "site_a" / "modes.json").read_text())
    assert len(modes["windows"]) == 2 * N_BAGS_A


def test_a_bag_without_structure_file_is_named(tmp_path, archive):
    import shutil

    bag = tmp_path / "lonely" / "bag"
    shutil.copytree(archive / "site_a" / "day_00" / "bag", bag)
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "batch", str(tmp_path / "lonely"),
                          "--out", str(tmp_path / "o"), "--engine", "serial"], capture_output=True, text=True)
    assert run.returncode == 2
    assert str(bag) in run.stderr and "structure" in run.stderr
    assert not (tmp_path / "o").exists()  # nothing half-written
