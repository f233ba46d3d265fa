"""Importers never leave a partial bag and refuse what a bag cannot hold: stamps outside 1970-2038
(a ROS time's seconds are 32 bits), a CSV with a header and no rows, an empty array; a failed
import leaves nothing, so a rerun is not blocked."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.cli import main
from shm_ros.io.importers import ImportedRecord, ImportFileError, read_csv, read_npy, write_bag


@pytest.mark.parametrize("start", ["1e12", "-5", "inf", "nan", "9999-01-01T00:00:00Z", "2040-01-01T00:00:00Z"])
def test_out_of_range_stamps_are_refused_and_nothing_is_left(tmp_path, start, capsys):
    (tmp_path / "a.csv").write_text("a,b\n" + "0.1,0.2\n" * 50)
    rc = main(["import", str(tmp_path / "a.csv"), "--rate", "100", "--start", start, "--out", str(tmp_path / "bag")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_time_column_out_of_range(tmp_path):
    (tmp_path / "t.csv").write_text("t,a\n1e300,0.1\n2e300,0.2\n")
    with pytest.raises(ImportFileError, match="outside 1970"):
        read_csv(tmp_path / "t.csv", time_column="t")


def test_csv_without_rows_and_empty_arrays(tmp_path):
    (tmp_path / "h.csv").write_text("a,b\n")
    with pytest.raises(ImportFileError, match="no data rows"):
        read_csv(tmp_path / "h.csv", sample_rate_hz=100.0)
    np.save(tmp_path / "e.npy", np.zeros((0, 2)))
    with pytest.raises(ImportFileError, match="with samples"):
        read_npy(tmp_path / "e.npy", sample_rate_hz=100.0)
    np.save(tmp_path / "c.npy", np.zeros((5, 2), complex))
    with pytest.raises(ImportFileError, match="real"):
        read_npy(tmp_path / "c.npy", sample_rate_hz=100.0)


def test_a_failed_write_leaves_no_bag_and_a_rerun_works(tmp_path, monkeypatch):
    rec = ImportedRecord(["a"], np.zeros((500, 1)), 100.0, 1_714_521_600_000_000_000)
    import shm_ros.io.bags as bags

    real = bags.BagWriter.accel_block
    calls = {"n": 0}

    def dies(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(28, "No space left on device")
        return real(self, *a, **k)

    monkeypatch.setattr(bags.BagWriter, "accel_block", dies)
    from shm_ros.io.atomic import DiskFullError

    with pytest.raises(DiskFullError, match="no space left"):
        write_bag([rec], tmp_path / "bag")
    assert list(tmp_path.iterdir()) == []  # no partial bag, no temporary folder
    monkeypatch.setattr(bags.BagWriter, "accel_block", real)
    summary = write_bag([rec], tmp_path / "bag")
    assert summary["messages"] == 5 and (tmp_path / "bag" / "metadata.yaml").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
    files = sorted(p.name for p in (tmp_path / "bag").iterdir())
    assert files == ["bag.mcap", "metadata.yaml"], files  # named after the bag, not the temporary name
    with pytest.raises(ImportFileError, match="already exists"):
        write_bag([rec], tmp_path / "bag")
