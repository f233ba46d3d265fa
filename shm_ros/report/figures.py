"""Writing a finished matplotlib figure (one place for the layout, folders and closing)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def save_figure(fig: Any, path: str | Path, **savefig: Any) -> Path:
    """Tight layout, create the folder, write ``path`` (format by suffix), close the figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, **savefig)
    plt.close(fig)
    return path
