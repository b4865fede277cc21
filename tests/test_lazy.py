"""Deferred imports: a stage that runs gets whole modules."""

import subprocess
import sys
from types import ModuleType

from rd_pipeline import lazy
from rd_pipeline.lazy import lazy_import, load_deferred

LOADS_THEN_IMPORTS_SUBMODULE = """
import types
from rd_pipeline.lazy import lazy_import, load_deferred
torch = lazy_import("torch")
load_deferred()
import torch.distributed
print(type(torch) is types.ModuleType, torch.distributed.is_available())
"""


def test_load_deferred_lets_a_submodule_import():
    # Without load_deferred this import aborts the interpreter (torch 2.13, Python 3.11) or raises
    # (torch 2.11, Python 3.12.3), so it runs in a process of its own.
    result = subprocess.run(
        [sys.executable, "-c", LOADS_THEN_IMPORTS_SUBMODULE], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["True", "True"]


DELETES_OWN_ATTRIBUTE = """
import sys
helper = 1
delattr(sys.modules[__name__], "helper")
kept = 2
"""


def test_a_module_deleting_its_own_attribute_loads(tmp_path, monkeypatch):
    # torch deletes helpers from itself while it loads; CPython 3.12.3's LazyLoader recursed on it.
    (tmp_path / "self_deleting.py").write_text(DELETES_OWN_ATTRIBUTE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "self_deleting", raising=False)
    module = lazy_import("self_deleting")
    load_deferred()
    assert module.kept == 2
    assert not hasattr(module, "helper")


def test_a_broken_lazy_loader_imports_at_once(tmp_path, monkeypatch):
    (tmp_path / "loaded_at_once.py").write_text("value = 3\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "loaded_at_once", raising=False)
    monkeypatch.setattr(lazy, "LAZY_LOADER_BROKEN", True)
    module = lazy_import("loaded_at_once")
    assert type(module) is ModuleType
    assert vars(module)["value"] == 3
