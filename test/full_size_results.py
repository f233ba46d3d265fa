"""The figures of the full-size acceptance runs that the docs quote, in one committed file.

A full-size run (``SHM_FULL=1``) writes its figures with :func:`record` into
``docs/results/full_size.json`` (one section per run: the figures as the docs write them, the
command, the date and the commit); ``test/test_documented_results.py`` (in CI) checks that every
figure the docs quote equals that file's. So after a full-size run either the docs are brought to
its figures or that test fails.
"""

from __future__ import annotations

import json
import subprocess
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "full_size.json"


def recorded() -> dict[str, Any]:
    """Every run's section of the results file."""
    return json.loads(RESULTS.read_text(encoding="utf-8"))


def record(section: str, figures: dict[str, str], command: str) -> None:
    """Write ``figures`` (as the docs print them) as the latest full-size run of ``section``."""
    head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, cwd=ROOT)
    doc = recorded() if RESULTS.is_file() else {}
    doc[section] = {"command": command, "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
                    "commit": head.stdout.strip() or None, "figures": figures}
    RESULTS.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n", encoding="utf-8")
