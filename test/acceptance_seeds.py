"""Acceptance seeds derived from the git tree of ``shm_ros/core``: no seed is chosen by hand, and a
change of the core draws new ones (the figures in the docs name the tree they were run at)."""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def core_tree() -> str:
    """The git tree hash of ``shm_ros/core`` at HEAD ("" outside a git checkout)."""
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD:shm_ros/core"], capture_output=True,
                             text=True, check=True, timeout=30)
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def acceptance_seeds(n: int, tree: str | None = None) -> list[int]:
    """``n`` campaign seeds from the core's tree hash (0.. without git)."""
    tree = core_tree() if tree is None else tree
    base = int(hashlib.sha256(tree.encode()).hexdigest()[:6], 16) if tree else 0
    return [base + k for k in range(n)]


DEV_SEEDS = 1_000_000  # development seeds are 0 .. DEV_SEEDS - 1; acceptance seeds are never below it
ACCEPTANCE_SPAN = 1_000_000_000


def explain_seeds(n: int, tree: str, row: str) -> list[int]:
    """``n`` acceptance seeds of one row of explain's acceptance (bench/explain_acceptance.py) from the
    git tree of ``shm_ros/core`` (which holds the shipped threshold files), in [DEV_SEEDS,
    DEV_SEEDS + ACCEPTANCE_SPAN): disjoint from the development seeds, and drawn by the hash alone."""
    base = int(hashlib.sha256(f"{tree}:{row}".encode()).hexdigest()[:12], 16) % ACCEPTANCE_SPAN
    return [DEV_SEEDS + (base + k) % ACCEPTANCE_SPAN for k in range(n)]
