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
