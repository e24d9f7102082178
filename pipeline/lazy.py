"""Packages whose public names are imported on first use (PEP 562's module `__getattr__`):
a process loads only the modules its run takes (docs/reruns.md, "A rerun that renders
nothing": `motion.pipeline.bake` and `motion.pipeline.shot`)."""

from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping


def lazy_names(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """The `__getattr__` of package `package`: each name of `homes` (name -> the package's
    module that defines it) from its module, imported now; AttributeError for any other."""

    def __getattr__(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{home}"), name)

    return __getattr__
