"""What an archive holds: its bags, and the structure file each bag belongs to."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

STRUCTURE_NAMES = ("structure.yaml", "structure.yml")


@dataclass(frozen=True)
class ArchiveBag:
    bag: str
    structure: str


def is_bag(path: Path) -> bool:
    """A rosbag2 folder (metadata.yaml, or storage files of a bag whose recorder was killed) or a
    single ``.mcap`` file."""
    if path.is_file():
        return path.suffix == ".mcap"
    if not path.is_dir():
        return False
    return (path / "metadata.yaml").is_file() or any(path.glob("*.mcap")) or any(path.glob("*.db3"))


def find_bags(roots: Iterable[str | Path]) -> list[Path]:
    """Every bag under ``roots`` (a root may itself be a bag), sorted by path; a bag's own folder is
    not searched further."""
    found: list[Path] = []

    def walk(p: Path) -> None:
        if is_bag(p):
            found.append(p)
            return
        if p.is_dir():
            for child in sorted(p.iterdir()):
                if child.is_dir() or child.suffix == ".mcap":
                    walk(child)

    for root in roots:
        r = Path(root)
        if not r.exists():
            raise FileNotFoundError(f"{r}: no such file or directory")
        walk(r)
    return sorted(set(found))


def structure_of(bag: Path, default: str | Path | None = None) -> Path:
    """``default`` when given, else the nearest ``structure.yaml`` in the bag's folder or above it."""
    if default is not None:
        return Path(default)
    for folder in [bag, *bag.parents] if bag.is_dir() else list(bag.parents):
        for name in STRUCTURE_NAMES:
            if (folder / name).is_file():
                return folder / name
    raise FileNotFoundError(f"{bag}: no structure file given (--structure) and no "
                            f"{STRUCTURE_NAMES[0]} next to the bag or in a folder above it")


def archive(roots: Iterable[str | Path], structure: str | Path | None = None) -> list[ArchiveBag]:
    bags = find_bags(roots)
    if not bags:
        raise FileNotFoundError(f"no bag found under {', '.join(str(r) for r in roots)}")
    return [ArchiveBag(str(b), str(structure_of(b, structure))) for b in bags]
