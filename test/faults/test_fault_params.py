"""Fault matrix, node-parameter rows: policy and estimator refuse bad parameters at start.

Like sim_bridge and the recorder: an unknown name (a typo), a non-finite number, a value out
of range or outside its choices stops the node with exit 2 and one line naming the parameter
and what is allowed, never a traceback and never a node that runs on a silent default.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from live_fixtures import node, tiny_checkpoint
from ros_harness import ProcessGroup

pytestmark = pytest.mark.ros

CASES = [
    ('policy', 'determinstic:=true', "unknown parameter(s) ['determinstic']"),
    ('policy', 'noise:=.nan', 'parameter noise must be a finite number, got nan'),
    ('policy', 'context_deadline:=.inf', 'parameter context_deadline must be a finite number'),
    ('policy', 'context_lag:=17', 'parameter context_lag must be <= 16, got 17'),
    ('policy', 'mode:=sideways', "parameter mode='sideways' is not allowed; choose one of "
     'lockstep, realtime'),
    ('policy', 'device:=cuda', "cannot load on device 'cuda'"),
    ('context_estimator', 'mode:=sideways', "parameter mode='sideways' is not allowed"),
    ('context_estimator', 'torch_threads:=0', 'parameter torch_threads must be >= 1, got 0'),
    ('context_estimator', 'image_size:=.nan', 'parameter image_size must be an integer'),
]


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One small real checkpoint for every case."""
    return tiny_checkpoint(tmp_path_factory.mktemp('params') / 'tiny.pt')


@pytest.mark.parametrize(('name', 'param', 'needle'), CASES)
def test_a_bad_parameter_stops_the_node_with_one_line(
        ros_processes: ProcessGroup, checkpoint: Path, name: str, param: str,
        needle: str) -> None:
    """Exit 2, one `error:` line naming the parameter; nothing else printed."""
    label = f'param-{name}-{param.split(":=")[0]}'
    process = ros_processes.start(label, node(name, f'checkpoint:={checkpoint}', param))
    assert process.wait(timeout=60) == 2, ros_processes.log_text(label)
    log = ros_processes.log_text(label)
    assert log.startswith(f'error: {name}: ') and log.count('\n') == 1, log
    assert needle in log, log
