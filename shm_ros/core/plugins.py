"""Registries of named classes that extend the pipeline without editing it (structure kinds, truth models).

A :class:`KindRegistry` maps a name to a class. Classes register themselves with the registry's
``register(name)`` decorator when their module is imported; the registry imports, the first time a
name is looked up:

* every module of its built-in package (e.g. ``shm_ros/core/models/kinds/``): a new built-in kind is
  one new file there;
* the modules of the entry-point group ``shm_ros.model_kinds`` (``[project.entry-points]`` of an
  installed distribution), so a separate package can add kinds;
* the ``.py`` files (or directories of them) listed in the environment variable ``SHM_ROS_KINDS``
  (separated by ``os.pathsep``), so a user can add a kind without packaging anything.

:func:`load_kind_module` loads one more file or module explicitly. One external module may register
into several registries (a model kind and its truth model), so external modules are loaded once per
process for all registries.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import pkgutil
import sys
from collections.abc import Callable, Iterator
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType
from typing import Generic, TypeVar

ENTRY_POINT_GROUP = "shm_ros.model_kinds"
ENV_VAR = "SHM_ROS_KINDS"

T = TypeVar("T")

_external_loaded = False
_loaded_files: dict[Path, ModuleType] = {}


class KindRegistry(Generic[T]):
    """Name -> class, filled by ``@registry.register(name)``; ``what`` names the entries in messages."""

    def __init__(self, what: str, package: str):
        self.what = what
        self.package = package
        self._classes: dict[str, type[T]] = {}
        self._discovered = False

    def register(self, name: str) -> Callable[[type[T]], type[T]]:
        """Class decorator: make the class the ``name`` entry (its ``name`` attribute is set)."""

        def deco(cls: type[T]) -> type[T]:
            old = self._classes.get(name)
            if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
                raise ValueError(f"{self.what} {name!r} is registered twice ({_where(old)} and {_where(cls)})")
            cls.name = name  # type: ignore[attr-defined]  # every registered class carries its name
            self._classes[name] = cls
            return cls

        return deco

    def unregister(self, name: str) -> None:
        """Forget ``name`` (tests that register a temporary kind)."""
        self._classes.pop(name, None)

    def get(self, name: str) -> type[T]:
        """The class registered as ``name``; KeyError listing the known names otherwise."""
        self.discover()
        try:
            return self._classes[name]
        except KeyError:
            raise KeyError(f"unknown {self.what} {name!r} (known: {', '.join(self.names())})") from None

    def instance(self, name: str) -> T:
        """An instance of the class registered as ``name``; ValueError listing the known names otherwise
        (for settings that name a plug-in)."""
        try:
            cls = self.get(str(name))
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None
        return cls()

    def __contains__(self, name: object) -> bool:
        self.discover()
        return name in self._classes

    def names(self) -> list[str]:
        self.discover()
        return sorted(self._classes)

    def __iter__(self) -> Iterator[type[T]]:
        self.discover()
        return iter([self._classes[n] for n in sorted(self._classes)])

    def discover(self) -> None:
        """Import the built-in package's modules and the external kind modules (once)."""
        if self._discovered:
            return
        self._discovered = True  # first: a module being imported may look a name up
        try:
            pkg = importlib.import_module(self.package)
            for info in pkgutil.iter_modules(pkg.__path__, prefix=self.package + "."):
                importlib.import_module(info.name)
            load_external_kinds()
        except BaseException:
            self._discovered = False  # a module that failed to import is tried again, not left out
            raise


def _where(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def load_external_kinds() -> None:
    """Load the entry-point group and the ``SHM_ROS_KINDS`` files, once per process."""
    global _external_loaded
    if _external_loaded:
        return
    _external_loaded = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        ep.load()
    for item in filter(None, os.environ.get(ENV_VAR, "").split(os.pathsep)):
        p = Path(item)
        for f in sorted(p.glob("*.py")) if p.is_dir() else [p]:
            load_kind_module(f)


def load_kind_module(source: str | Path) -> ModuleType:
    """Import a kind module: a ``.py`` file path or a dotted module name. A file is loaded once."""
    p = Path(source)
    if p.suffix != ".py":
        return importlib.import_module(str(source))
    p = p.resolve()
    if p in _loaded_files:
        return _loaded_files[p]
    if not p.is_file():
        raise FileNotFoundError(f"kind module {str(p)!r} not found")
    name = f"shm_ros_kind_{p.stem}_{abs(hash(str(p))):x}"
    spec = importlib.util.spec_from_file_location(name, p)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load kind module {str(p)!r}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while the file executes
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    _loaded_files[p] = module
    return module
