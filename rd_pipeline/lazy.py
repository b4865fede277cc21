"""Deferred imports for the modules that define stage parameters.

Every command plans the whole DAG, so it imports every stage's params; those live beside torch code
(reward terms, samplers). Importing torch there costs seconds that a `run --until retarget` should
not pay, so these modules take torch from `lazy_import`: a stand-in that imports the real module on
its first attribute access.

The stand-in is not put in `sys.modules`. The standard library's `LazyLoader` puts a half-loaded
module there, and libraries look there: scipy's array checks ask `sys.modules["torch"]` for its
`Tensor` type on every rotation, which loaded torch during the first stage anyway, and importing a
submodule (`torch.distributed`) of the half-loaded module aborted the process (torch 2.13, Python
3.11). Here `torch` is in `sys.modules` only once it is imported, whole.
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import Any


class _Deferred(ModuleType):
    """Stands in for the module of its name until an attribute is asked for."""

    def __getattr__(self, attribute: str) -> Any:
        # Called only for attributes not yet copied: the first access, and any the module adds later.
        module = importlib.import_module(self.__name__)
        vars(self).update(vars(module))
        return getattr(module, attribute)


def lazy_import(name: str) -> ModuleType:
    """The module `name` if it is already imported, else a stand-in that imports it on first use."""
    return sys.modules.get(name) or _Deferred(name)
