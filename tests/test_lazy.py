"""Deferred imports: a stage that runs gets whole modules."""

import subprocess
import sys

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
