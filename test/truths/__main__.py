"""``python -m truths KIND [KIND ...] --seed N --size reduced|full --out DIR`` (run from ``test/``):
write campaigns and print where they are and the expected answer."""

from __future__ import annotations

import argparse
from pathlib import Path

from .registry import KINDS, make_campaign


def main() -> None:
    ap = argparse.ArgumentParser(prog="python -m truths", description="write truth campaigns")
    ap.add_argument("kinds", nargs="+", choices=[*KINDS, "all"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", default="reduced", choices=["reduced", "full"])
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    kinds = KINDS if "all" in args.kinds else args.kinds
    for kind in kinds:
        c = make_campaign(kind, args.seed, args.size, args.out / f"{kind}-{args.seed}-{args.size}")
        print(f"{kind:28s} {c.expected:34s} {c.directory}")


if __name__ == "__main__":
    main()
