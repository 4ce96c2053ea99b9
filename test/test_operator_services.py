"""Operator services with real processes: each reachable and doing its job; the atomic swap.

One lockstep loop (sim_bridge, context_estimator, policy) and a continual_trainer. The pair is
swapped 20 times through continual_trainer's ~/swap_checkpoint between two tiny checkpoints
while the loop runs: the policy never refuses an estimate (`mismatched` stays 0) and every
step's action is the one of the checkpoint whose sha256 its estimate carries (issue 48).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest

from live_fixtures import TASK, node, tiny_checkpoint
from ros_harness import ProcessGroup, driver_node, python_module, spin_until

pytestmark = pytest.mark.ros

SERVICES = {
    '/policy/freeze_context': 'std_srvs/srv/SetBool',
    '/policy/stage_checkpoint': 'zeus_msgs/srv/SwapCheckpoint',
    '/sim_bridge/reset_episode': 'std_srvs/srv/Trigger',
    '/continual_trainer/pause': 'std_srvs/srv/SetBool',
    '/continual_trainer/run_round_now': 'std_srvs/srv/Trigger',
    '/continual_trainer/swap_checkpoint': 'zeus_msgs/srv/SwapCheckpoint',
}
SWAPS = 20


def _call(probe: Any, client: Any, request: Any, timeout: float = 20.0) -> Any:
    future = client.call_async(request)
    assert spin_until(probe, future.done, timeout), f'no answer from {client.srv_name}'
    return future.result()


def test_operator_services_and_twenty_atomic_swaps(ros_processes: ProcessGroup,
                                                   tmp_path: Path) -> None:
    """Every operator service answers and acts; 20 swaps, no step on a mismatched pair."""
    from diagnostic_msgs.msg import DiagnosticArray
    import numpy as np
    from std_srvs.srv import SetBool, Trigger
    from test_ros_citizen import newest_status
    import torch
    from zeus_msgs.msg import Action, ContextEstimate, StateVector, StepFeedback
    from zeus_msgs.srv import SwapCheckpoint

    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.nodes.topics import step_qos

    a, b = tiny_checkpoint(tmp_path / 'a.pt'), tiny_checkpoint(tmp_path / 'b.pt', seed=1)
    sha = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b)}
    ros_processes.start('ops-sim_bridge', node('sim_bridge', f'task:={TASK}',
                                               'min_observers:=2', 'action_timeout:=5.0'))
    for name in ('context_estimator', 'policy'):
        ros_processes.start(f'ops-{name}', node(name, f'checkpoint:={a}'))
    trainer = ros_processes.start('ops-trainer', python_module(
        'zeus_ros.nodes.continual_node', '--ros-args', '-p', f'recording:={tmp_path / "rec"}',
        '-p', f'checkpoint:={a}', '-p', 'poll_s:=0.2', '-p', 'novelty_window:=0'))
    torch.set_num_threads(1)
    agents = {sha[p]: InferenceAgent.from_checkpoint(p) for p in (a, b)}
    states: dict[int, Any] = {}
    contexts: dict[int, tuple[str, Any]] = {}
    actions: dict[int, Any] = {}
    firsts: list[int] = []
    diagnostics: list[Any] = []
    with driver_node(ros_processes.domain_id) as probe:
        probe.create_subscription(StateVector, 'zeus/observation/state',
                                  lambda m: states.__setitem__(
                                      m.step, np.asarray(m.data, np.float32)), step_qos(100))
        probe.create_subscription(ContextEstimate, 'zeus/context', lambda m: contexts.__setitem__(
            m.step, (m.checkpoint_sha256, np.asarray(m.data, np.float32))), step_qos(100))
        probe.create_subscription(Action, 'zeus/action', lambda m: actions.__setitem__(
            m.step, np.asarray(m.data, np.float32)), step_qos(100))
        probe.create_subscription(StepFeedback, 'zeus/step', lambda m: firsts.append(m.step)
                                  if m.first else None, step_qos(100))
        probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 50)
        types = {'SetBool': SetBool, 'Trigger': Trigger, 'SwapCheckpoint': SwapCheckpoint}
        clients = {name: probe.create_client(types[kind.rsplit('/', 1)[1]], name)
                   for name, kind in SERVICES.items()}
        assert all(c.wait_for_service(timeout_sec=60) for c in clients.values()), \
            ros_processes.log_text('ops-trainer')[-2000:]
        listed = dict(probe.get_service_names_and_types())
        assert {n: listed.get(n, [''])[0] for n in SERVICES} == SERVICES
        assert spin_until(probe, lambda: len(actions) > 10, timeout=60)

        # Bad requests: refused with one line, nothing changes.
        swap = clients['/continual_trainer/swap_checkpoint']
        for bad in (SwapCheckpoint.Request(checkpoint=str(tmp_path / 'missing.pt')),
                    SwapCheckpoint.Request(checkpoint=str(b), expect_sha256=sha[a]),
                    SwapCheckpoint.Request(checkpoint=str(b), expect_sha256='zz')):
            answer = _call(probe, swap, bad)
            assert not answer.success and '\n' not in answer.message and answer.message, answer
        assert {s for s, _ in contexts.values()} == {sha[a]}

        # 20 swaps while the loop runs, alternating b, a, ...; each followed by the policy.
        for turn in range(SWAPS):
            target = (b, a)[turn % 2]
            answer = _call(probe, swap, SwapCheckpoint.Request(
                checkpoint=str(target), expect_sha256=sha[target]))
            assert answer.success and answer.sha256 == sha[target], answer.message
            since, stamp = max(contexts), sha[target]
            assert spin_until(probe, lambda since=since, stamp=stamp: any(
                s == stamp and step in actions and step > since
                for step, (s, _) in contexts.items()), timeout=20), f'swap {turn}'
        last = max(actions)
        assert spin_until(probe, lambda: max(actions) > last + 3, timeout=20)
        checked = [s for s in sorted(actions) if s in contexts and s in states]
        assert len(checked) > 2 * SWAPS
        for step in checked:  # each action is that of the checkpoint its estimate came from
            stamp, context = contexts[step]
            expected = agents[stamp].act(states[step], context, deterministic=True)
            np.testing.assert_allclose(actions[step], expected, atol=1e-4,
                                       err_msg=f'step {step}')
        assert len({s for s, _ in contexts.values()}) == 2
        seen = len(diagnostics)
        assert spin_until(probe, lambda: newest_status(diagnostics[seen:], '/policy'), 5)
        policy = newest_status(diagnostics[seen:], '/policy')
        assert policy['mismatched'] == '0' and policy['safe'] == '0', policy

        # psi frozen and live again; an episode reset; the trainer paused, resumed, asked.
        freeze = clients['/policy/freeze_context']
        answer = _call(probe, freeze, SetBool.Request(data=True))
        assert answer.success and 'frozen' in answer.message, answer.message
        answer = _call(probe, freeze, SetBool.Request(data=False))
        assert answer.success and 'live' in answer.message, answer.message
        reset_at = max(actions)
        answer = _call(probe, clients['/sim_bridge/reset_episode'], Trigger.Request())
        assert answer.success, answer.message
        assert spin_until(probe, lambda: any(s > reset_at for s in firsts), timeout=10), firsts
        pause = clients['/continual_trainer/pause']
        assert _call(probe, pause, SetBool.Request(data=True)).success
        answer = _call(probe, clients['/continual_trainer/run_round_now'], Trigger.Request())
        assert not answer.success and 'paused' in answer.message, answer.message
        assert _call(probe, pause, SetBool.Request(data=False)).success
        answer = _call(probe, clients['/continual_trainer/run_round_now'], Trigger.Request())
        assert not answer.success and 'no closed split' in answer.message, answer.message
    assert trainer.poll() is None, ros_processes.log_text('ops-trainer')[-2000:]
    history = (tmp_path / 'rec_continual' / 'history.jsonl').read_text()
    assert history.count('"operator_swap"') == SWAPS
