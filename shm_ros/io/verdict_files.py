"""verdict.json (docs/interfaces.md §5) and the numbers behind explain's figures (explain_series.json)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from shm_ros.core.provenance import stamp_output
from shm_ros.io import jsonio

VERDICT = "verdict.json"
SERIES = "explain_series.json"


def write_verdict(out: str | Path, verdict: Any, config: dict[str, Any] | None = None,
                  seed: int | None = None) -> Path:
    """``out/verdict.json`` (with ``schema_version`` and ``provenance``) and ``out/explain_series.json``
    (per window: times, covariates, residuals before and after, training mask, fitted forms)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    jsonio.dump(getattr(verdict, "figures", {}) or {}, out / SERIES)
    return jsonio.dump(stamp_output(verdict.to_dict(), config, seed), out / VERDICT, indent=2)


def read_verdict(path: str | Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(verdict, series) from a folder or a verdict.json; series is {} when absent."""
    p = Path(path)
    p = p / VERDICT if p.is_dir() else p
    verdict = jsonio.loads(p.read_text(encoding="utf-8"))
    s = p.with_name(SERIES)
    series = jsonio.loads(s.read_text(encoding="utf-8")) if s.is_file() else {}
    return verdict, series
