"""The continual trainer node's round in a child process (zeus_ros/nodes/continual_node.py).

`run_child_round` with stand-in children (plain Python, no training): the answer is read from
the result file, the child's stdout is logged line by line, a child that dies without an
answer is a failure carrying its last stderr lines, and a shutdown stops a child that ignores
SIGTERM (SIGKILL after the grace). No ROS process starts; the node module needs rclpy.
"""

from __future__ import annotations

import json
from pathlib import Path
import sys
import threading
import time

import pytest

from ros_harness import require_ros

ANSWER = {'status': 'done', 'candidate': '/c.pt', 'sha256': 'ab' * 32, 'deploy': True,
          'reason': 'gain', 'gain': 3.0, 'se': 1.0, 'required': 2.0, 'summary': 's',
          'resume_from': None, 'episode_length': 40}


def _child(monkeypatch: pytest.MonkeyPatch, code: str) -> object:
    require_ros()
    from zeus_ros.nodes import continual_node

    monkeypatch.setattr(continual_node, 'ROUND_COMMAND', (sys.executable, '-c', code))
    monkeypatch.setattr(continual_node, 'STOP_GRACE_S', 0.5)
    return continual_node


def _request(folder: Path) -> dict:
    return {'threads': 1, 'result': str(folder / 'result.json'), 'parent_pid': 0}


def test_a_round_child_answers_in_its_result_file(monkeypatch: pytest.MonkeyPatch,
                                                  tmp_path: Path) -> None:
    code = ('import json, os, sys; request = json.load(open(sys.argv[-1])); '
            "print('continual: DEPLOY candidate.pt', flush=True); "
            f"open(request['result'], 'w').write(json.dumps({ANSWER!r})); "
            "assert os.environ['OMP_NUM_THREADS'] == '1'")
    node = _child(monkeypatch, code)
    logged: list[str] = []
    answer = node.run_child_round(tmp_path / 'round_001', _request(tmp_path / 'round_001'),
                                  logged.append, threading.Event())
    assert answer == {**ANSWER, 'stderr': []}
    assert logged == ['continual: DEPLOY candidate.pt']
    assert json.loads((tmp_path / 'round_001' / 'request.json').read_text())['threads'] == 1


def test_a_child_without_an_answer_is_a_failure_with_its_stderr(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    code = ("import sys; print('first', file=sys.stderr); "
            "print('MemoryError: out of memory', file=sys.stderr); sys.exit(3)")
    node = _child(monkeypatch, code)
    answer = node.run_child_round(tmp_path, _request(tmp_path), print, threading.Event())
    assert answer['status'] == 'failed' and answer['error'] == 'RoundProcessError'
    assert 'exited with code 3' in answer['reason'] and 'out of memory' in answer['reason']
    assert answer['stderr'] == ['first', 'MemoryError: out of memory']


def test_a_shutdown_stops_the_child_sigkill_after_the_grace(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    code = ('import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); '
            "print('ready', flush=True); time.sleep(60)")
    node = _child(monkeypatch, code)
    stop = threading.Event()
    logged: list[str] = []

    def stop_when_ready() -> None:
        while 'ready' not in logged:
            time.sleep(0.05)
        stop.set()

    threading.Thread(target=stop_when_ready, daemon=True).start()
    begin = time.monotonic()
    answer = node.run_child_round(tmp_path, _request(tmp_path), logged.append, stop)
    assert answer == {'status': 'stopped'}
    assert time.monotonic() - begin < 30


def test_a_round_that_finished_counts_even_when_the_shutdown_came_late(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Its gate line is written: the answer counts (SIGTERM ignored, SIGKILL after the grace)."""
    code = ('import json, signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); '
            'request = json.load(open(sys.argv[-1])); '
            f"open(request['result'], 'w').write(json.dumps({ANSWER!r})); "
            "print('ready', flush=True); time.sleep(60)")
    node = _child(monkeypatch, code)
    stop = threading.Event()
    answer = node.run_child_round(tmp_path, _request(tmp_path),
                                  lambda line: stop.set(), stop)
    assert answer == {**ANSWER, 'stderr': []}
