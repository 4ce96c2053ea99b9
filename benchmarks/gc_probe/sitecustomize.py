"""Count Python's garbage collections in every process of a benchmark (issue 14, session 17).

Why: a full collection over a heap holding torch modules takes tens of milliseconds, so if the
nodes collected while stepping, that would be a cause of the live loop's p99 latency. Python
imports `sitecustomize` at start-up from PYTHONPATH, so putting this folder first reaches the
benchmark and the nodes it starts alike:

    export ZEUS_GC_PROBE_DIR=out/gc PYTHONPATH=benchmarks/gc_probe:$PYTHONPATH
    python benchmarks/bench_live_loop.py --kinds state --modes multi,single --steps 4000
    cat out/gc/*.txt

Each process rewrites `<script>_<pid>.txt` every second (nodes are stopped by a signal, so
there is no reliable exit hook): collections per generation during start-up (the first
ZEUS_GC_PROBE_WARMUP seconds, default 8) and after it, with their total and longest pause.
Without ZEUS_GC_PROBE_DIR it does nothing.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time

_DIR = os.environ.get('ZEUS_GC_PROBE_DIR', '')
_WARMUP = float(os.environ.get('ZEUS_GC_PROBE_WARMUP', '8'))
_BORN = time.monotonic()
_events: list[tuple[int, float, float]] = []  # (generation, seconds since start, pause s)
_started = [0.0]


def _on_collection(phase: str, info: dict) -> None:
    """gc.callbacks hook: time each collection."""
    if phase == 'start':
        _started[0] = time.perf_counter()
    else:
        _events.append((info['generation'], time.monotonic() - _BORN,
                        time.perf_counter() - _started[0]))


def _summary() -> str:
    """Per phase and generation: count, total and longest pause."""
    lines = [' '.join(sys.argv[:2]), f'lived {time.monotonic() - _BORN:.1f} s']
    for phase, keep in (('start-up', lambda t: t < _WARMUP), ('after', lambda t: t >= _WARMUP)):
        for generation in (0, 1, 2):
            pauses = [p for g, t, p in list(_events) if g == generation and keep(t)]
            if pauses:
                lines.append(f'{phase} gen{generation}: {len(pauses)} collections, total '
                             f'{sum(pauses) * 1e3:.1f} ms, longest {max(pauses) * 1e3:.2f} ms')
        if not any(keep(t) for _, t, _ in list(_events)):
            lines.append(f'{phase}: no collections')
    return '\n'.join(lines) + '\n'


def _write_every_second() -> None:
    """Rewrite this process's summary (whole, through a rename) every second."""
    while True:
        time.sleep(1.0)  # by now `python -m` has put the module's path in sys.argv[0]
        name = os.path.splitext(os.path.basename(sys.argv[0] or 'python'))[0]
        path = os.path.join(_DIR, f'{name}_{os.getpid()}.txt')
        with open(path + '.tmp', 'w') as out:
            out.write(_summary())
        os.replace(path + '.tmp', path)


if _DIR:
    os.makedirs(_DIR, exist_ok=True)
    gc.callbacks.append(_on_collection)
    threading.Thread(target=_write_every_second, daemon=True, name='gc-probe').start()
