"""`python -m bench [NAME ...] [-- ARGS]`: run benchmarks at full size (all of them by default).

Each ``bench/bench_<name>.py`` is also runnable alone (``python -m bench.bench_<name> --help``);
figures are written to ``bench/results/`` and summarised in ``docs/benchmarks.md``.
``refactor`` (CPU cost of two versions of the code side by side) runs only when named; the stress
run of the ROS tests is ``python -m bench.stress_ros``.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

NAMES = sorted(p.stem.removeprefix("bench_") for p in Path(__file__).parent.glob("bench_*.py"))
NOT_BY_DEFAULT = {"refactor"}  # a comparison between versions, not a figure of this one


def main(argv: list[str]) -> int:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__ + "\nbenchmarks: " + ", ".join(NAMES))
        return 0
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    names = [a for a in (argv[:argv.index("--")] if "--" in argv else argv)] or [
        n for n in NAMES if n not in NOT_BY_DEFAULT]
    unknown = [n for n in names if n not in NAMES]
    if unknown:
        print(f"unknown benchmark(s) {unknown}; known: {NAMES}", file=sys.stderr)
        return 2
    worst = 0
    for name in names:
        print(f"== bench {name}", flush=True)
        code = importlib.import_module(f"bench.bench_{name}").main(extra)
        worst = max(worst, int(code or 0))
    return worst


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
