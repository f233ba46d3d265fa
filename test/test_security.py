"""docs/security.md holds: bandit finds nothing above low severity in shm_ros/, and every kind of
low finding it reports is explained there with its count; the Fast DDS of the PyPI wheels has no
DDS-Security plugins (what the document says a wheel installation cannot do)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "security.md").read_text()


def test_bandit_finds_nothing_above_low_and_the_low_ones_are_explained():
    pytest.importorskip("bandit")
    out = subprocess.run([sys.executable, "-m", "bandit", "-r", "shm_ros", "-q", "-f", "json"], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    results = json.loads(out.stdout)["results"]
    above = [f"{r['filename']}:{r['line_number']} {r['test_id']} {r['issue_severity']}: {r['issue_text']}"
             for r in results if r["issue_severity"] != "LOW"]
    assert not above, "bandit findings above low severity:\n" + "\n".join(above)
    counts = Counter(r["test_id"] for r in results)
    for test_id, n in counts.items():
        row = re.search(rf"^\| {test_id} [^|]*\| (\d+) \|", DOC, re.M)
        assert row, f"docs/security.md does not explain bandit {test_id} ({n} findings)"
        assert int(row.group(1)) == n, f"docs/security.md says {row.group(1)} x {test_id}, bandit finds {n}"
    print(f"bandit: {sum(counts.values())} low findings ({dict(counts)}), none above low")


def test_the_pypi_fast_dds_has_no_security_plugins():
    libs = sorted((Path(sys.prefix) / "lib").glob("libfastdds.so*"))
    if not libs:
        pytest.skip("Fast DDS not from the PyPI wheels (a ROS installation): see docs/security.md")
    data = libs[0].read_bytes()
    assert b"DDS:Auth:PKI-DH" not in data and b"DDS:Crypto:AES-GCM-GMAC" not in data
    assert "built **without DDS-Security**" in DOC
