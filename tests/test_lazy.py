"""Deferred imports: torch is imported whole, on first use, and not before."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rd_pipeline.lazy import lazy_import

DEFERS_THEN_IMPORTS_SUBMODULE = """
import sys
from rd_pipeline.lazy import lazy_import
torch = lazy_import("torch")
print("torch" in sys.modules)
import torch.distributed
print(torch.distributed.is_available(), torch.zeros(2).shape[0])
"""


def test_a_deferred_module_is_not_imported_until_used_and_its_submodules_import():
    # A half-loaded torch in sys.modules aborted the interpreter on this import (torch 2.13,
    # Python 3.11), so it runs in a process of its own.
    result = subprocess.run(
        [sys.executable, "-c", DEFERS_THEN_IMPORTS_SUBMODULE], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["False", "True", "2"]


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
    assert "self_deleting" not in sys.modules
    assert module.kept == 2
    assert not hasattr(module, "helper")
    assert module.kept is sys.modules["self_deleting"].kept


RUNS_PARSE_THEN_SAYS_IF_TORCH_IMPORTED = """
import sys
from rd_pipeline.cli.app import main
code = main(["run", "--robot", "g1", "--motion", "dance1_subject2", "--until", "parse"])
print(code, "torch" in sys.modules)
"""


def test_a_stage_before_training_runs_without_importing_torch(tmp_path: Path) -> None:
    # Importing torch costs seconds of every `run --until retarget`; scipy's rotations look for
    # it in sys.modules, which imported it when a deferred stand-in was registered there.
    result = subprocess.run(
        [sys.executable, "-c", RUNS_PARSE_THEN_SAYS_IF_TORCH_IMPORTED],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "RD_ARTIFACTS": str(tmp_path / "store")},
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split()[-2:] == ["0", "False"]


def test_a_deferred_module_that_does_not_exist_says_so_on_use():
    module = lazy_import("rd_pipeline_no_such_module")
    with pytest.raises(ModuleNotFoundError, match="rd_pipeline_no_such_module"):
        _ = module.anything
