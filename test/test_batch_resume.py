"""A batch killed half-way and started again finishes with the same outputs as one uninterrupted
run, without identifying again the bags it had finished (shm_ros/batch/checkpoint.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from shm_ros.batch.archive import archive
from shm_ros.batch.engines import SerialEngine
from shm_ros.batch.jobs import BatchSettings
from shm_ros.batch.run import run_batch

N_BAGS = 4


class Killed(Exception):
    pass


class CountingEngine(SerialEngine):
    """Serial; counts the bag jobs it runs and dies (raises) after ``die_after`` of them."""

    def __init__(self, die_after: int | None = None) -> None:
        self.die_after = die_after
        self.bags_run: list[str] = []

    def map(self, fn, items, progress=None):
        def counted(item):
            if fn.__name__ == "identify_bag_kept":
                if self.die_after is not None and len(self.bags_run) == self.die_after:
                    raise Killed
                self.bags_run.append(item[0].bag)
            return fn(item)

        return super().map(counted, items, progress)


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import write_campaign

    root = tmp_path_factory.mktemp("archive")
    for k in range(N_BAGS):
        sc = named_scenario("girder")
        sc.n_windows, sc.window_s, sc.seed = 2, 60.0, 300 + k
        sc.start = f"2024-03-{1 + k:02d}T00:00:00Z"
        write_campaign(simulate_campaign(sc), root / f"day_{k}")
    spec = yaml.safe_load((root / "day_0" / "structure.yaml").read_text())
    spec.pop("parameters", None)  # tracking only: the update is not what is resumed
    (root / "structure.yaml").write_text(yaml.safe_dump(spec))
    for k in range(N_BAGS):
        (root / f"day_{k}" / "structure.yaml").unlink()
    return archive([root])


def _outputs(out: Path) -> dict[str, object]:
    def strip(doc):
        if isinstance(doc, dict):
            return {k: strip(v) for k, v in doc.items() if k not in ("provenance", "timing_s")}
        return [strip(v) for v in doc] if isinstance(doc, list) else doc

    return {str(p.relative_to(out)): strip(json.loads(p.read_text())) if p.suffix == ".json" else p.read_text()
            for p in sorted(out.rglob("*")) if p.is_file() and ".bags" not in p.parts}


def test_killed_batch_resumes_without_redoing_finished_bags(bags, tmp_path):
    settings = BatchSettings(window_s=60.0, track={"reference_windows": 3}, run_update=False)
    whole = CountingEngine()
    run_batch(bags, settings, whole, tmp_path / "whole", log=lambda s: None)
    assert len(whole.bags_run) == N_BAGS

    first = CountingEngine(die_after=N_BAGS // 2)
    with pytest.raises(Killed):
        run_batch(bags, settings, first, tmp_path / "resumed", log=lambda s: None)
    assert len(first.bags_run) == N_BAGS // 2
    lines: list[str] = []
    second = CountingEngine()
    run_batch(bags, settings, second, tmp_path / "resumed", log=lines.append)
    # only the bags the killed run had not finished, and nothing twice
    assert sorted(second.bags_run) == sorted(set(b.bag for b in bags) - set(first.bags_run))
    assert any(f"resuming: {N_BAGS // 2} of {N_BAGS} bags" in s for s in lines)
    assert _outputs(tmp_path / "resumed") == _outputs(tmp_path / "whole")
    assert not (tmp_path / "resumed" / ".bags").exists()  # finished: nothing kept

    # a killed batch started again with other settings takes nothing from the killed run
    with pytest.raises(Killed):
        run_batch(bags, settings, CountingEngine(die_after=1), tmp_path / "other", log=lambda s: None)
    again = CountingEngine()
    run_batch(bags, BatchSettings(window_s=60.0, track={"reference_windows": 4}, run_update=False), again,
              tmp_path / "other", log=lambda s: None)
    assert len(again.bags_run) == N_BAGS
