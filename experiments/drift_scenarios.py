"""benchmarks/bench_continual.py as a module: the drift scenarios, their values and seeds.

The benchmark owns them (SCENARIOS, REFERENCE_SEED, the context name of a task); the
experiments that re-measure its runs offline load it from here rather than copying them.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]


def bench_continual() -> ModuleType:
    """benchmarks/bench_continual.py, loaded by path (benchmarks/ is not a package)."""
    spec = importlib.util.spec_from_file_location('bench_continual',
                                                  REPO / 'benchmarks' / 'bench_continual.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
