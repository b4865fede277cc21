"""Deferred imports for the modules that define stage parameters.

Every command plans the whole DAG, so it imports every stage's params; those live beside torch code
(reward terms, samplers). Importing torch there costs seconds that a cached `run --until parse`
should not pay, so these modules take torch from `lazy_import`: the module object is created at
once and loaded on its first attribute access (the standard library's `LazyLoader`).

Importing a submodule (`torch.distributed`) of a module still deferred finds it half-loaded: on
torch 2.11 with Python 3.12.3 that raised an AttributeError, on torch 2.13 with Python 3.11 it
aborts the process. So code that runs, not plans, calls `load_deferred` first.

CPython 3.12.3's `LazyLoader` recurses without end when a module deletes one of its own attributes
while it loads (torch does; CPython gh-117178, fixed in 3.12.4). Ubuntu 24.04's Python and the GPU
lease's image are 3.12.3, so there modules load at once.
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType

_deferred: list[ModuleType] = []
"""Every module `lazy_import` deferred, loaded or not."""

LAZY_LOADER_BROKEN = sys.version_info[:3] == (3, 12, 3)
"""Whether this interpreter's `LazyLoader` has the self-deleting-attribute recursion."""


def lazy_import(name: str) -> ModuleType:
    """The module `name`, already imported or loaded on first use."""
    if name in sys.modules:
        return sys.modules[name]
    if LAZY_LOADER_BROKEN:
        return importlib.import_module(name)
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ModuleNotFoundError(f"No module named '{name}'", name=name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    _deferred.append(module)
    return module


def load_deferred() -> None:
    """Load every deferred module now (any attribute access loads one)."""
    for module in _deferred:
        vars(module)
