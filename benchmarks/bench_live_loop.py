"""End-to-end rate of the three-node loop next to the in-process loop doing the same work.

Both loops run the same task, schedule, networks (state_cpu / pixels_paper sizes) and
deployment code (ContextHistory + InferenceAgent, each frame encoded once as the nodes do): the
in-process loop calls them directly, the live loop runs sim_bridge, context_estimator and
policy in lockstep, as separate processes (multi) and as nodes of one process on one executor
(single, zeus launch --single-process, with intra-process delivery; single-dds: the same
without it, every message through DDS; pair: sim_bridge in its own process, the estimator and
the policy in one container, as `python -m zeus_ros.nodes.container --node context_estimator
... --node policy ...` runs them beside a robot's own driver). Observation-to-action latency
runs from StepFeedback k's source timestamp to Action k's: each stamped by the publishing
process's DDS writer when sim_bridge, then the policy, publishes, on the same machine clock, so
it is the time the loop took and nothing of the probe's (`p99 seen`: the probe's own callback
times, as before session 17, which add the probe's wake-ups: a Python process on the same
cores; `p99 bridge`: sim_bridge's own count over the run, from StepFeedback k published to
Action k received, the way back included, as its closing log line says: the one latency a run
with no outside reader has).
/proc gives each node's resident memory. The probe is itself an outside subscriber: the
container then publishes every step and action on DDS too. `single-quiet` runs the single mode
with no outside subscriber on the loop's topics (the rate comes from sim_bridge's step count on
/diagnostics, published at 1 Hz, its latency from sim_bridge's own count; the run is
sized from the round's in-process rate to last about QUIET_SECONDS, long enough for several
counts). `--executors
single,events` runs every mode once per executor the nodes spin on ($ZEUS_EXECUTOR,
nodes/spin.py), alternately in each round, so a loaded machine weighs on both alike.
`--context-lags 0,1` likewise runs every mode once per policy `context_lag` (shown as
`multi/lag1`): with a lag the policy acts on the context of an earlier step instead of waiting
for the estimator's answer to this one. `--split` also subscribes the probe to the context
topic and splits each step's period at the publishers' source timestamps into its three
segments (SEGMENTS): StepFeedback k -> ContextEstimate k (delivery to the estimator, its work,
its publish), -> Action k (the policy's), -> StepFeedback k + 1 (sim_bridge's); it costs the
estimator one more reader, so its rates are not those of a run without it.

    source scripts/env.sh && python benchmarks/bench_live_loop.py [--steps 400] \
        [--executors single,events] [--context-lags 0,1] [--split]
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
TASK = 'Cheetah-Run-v0'
SCHEDULE = {'kind': 'switch', 'every': 100, 'values': [0.6, 1.0, 1.4]}
SEGMENTS = ('estimator', 'policy', 'sim_bridge')
"""--split: the step's period, cut where each node publishes: StepFeedback k -> context k
(estimator), -> action k (policy), -> StepFeedback k + 1 (sim_bridge). Each segment holds the
delivery into its node, the node's work and its publish; the three add up to the period."""


def make_checkpoint(path: Path, obs_kind: str) -> Path:
    """An untrained checkpoint with the shipped config's network sizes (inference cost only)."""
    from sim_bridge.registry import make_task
    from zeus_ros.learning.agent import make_agent
    from zeus_ros.learning.checkpoint import save_checkpoint
    from zeus_ros.learning.config import load_config
    from zeus_ros.learning.spec import AgentSpec

    config_file = 'state_cpu.yaml' if obs_kind == 'state' else 'pixels_paper.yaml'
    config = load_config(REPO / 'params' / 'train' / config_file)
    task = make_task(TASK)
    low, high = task.action_bounds
    shape = (task.state_dim,) if obs_kind == 'state' else (9, 84, 84)
    spec = AgentSpec(task=TASK, context_names=task.context_names, obs_kind=obs_kind,
                     obs_shape=shape, action_dim=task.action_dim, action_low=low,
                     action_high=high,
                     obs_mean=np.zeros(shape, np.float32) if obs_kind == 'state' else None,
                     obs_std=np.ones(shape, np.float32) if obs_kind == 'state' else None)
    task.close()
    save_checkpoint(path, make_agent(config, spec, device='cpu'), step=0)
    return path


def in_process_rate(checkpoint: Path, steps: int) -> tuple[float, float, dict[str, float]]:
    """Steps/s, CPU ms per step and the mean ms of each node's part (SEGMENTS) in one process.

    ScheduledEnv + the deployment code: the parts are the estimator's (psi from the history,
    and pushing the transition into it), the policy's (acting) and sim_bridge's (stepping and,
    for pixels, rendering): what each node would do with no messages between them.
    """
    import torch

    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.learning.frames import FrameStack
    from zeus_ros.learning.inference import InferenceAgent

    torch.set_num_threads(1)
    agent = InferenceAgent.from_checkpoint(checkpoint, reuse_features=True)
    task = make_task(TASK, seed=0)
    env = ScheduledEnv(task, schedule_from_config(SCHEDULE, task, 0))
    history = agent.new_history()
    frames = FrameStack() if agent.obs_kind == 'pixels' else None

    def observe(result: object, first: bool) -> np.ndarray:
        if frames is None:
            return result.observation.state.astype(np.float32)
        frame = task.render(84, 84)
        return frames.reset(frame) if first else frames.push(frame)

    result = env.reset()
    obs = observe(result, True)
    parts = dict.fromkeys(SEGMENTS, 0.0)
    clock = time.perf_counter
    start, cpu = clock(), time.process_time()
    for _ in range(steps):
        t0 = clock()
        psi = agent.context(history)
        t1 = clock()
        action = agent.act(obs, psi)
        t2 = clock()
        result = env.step(action)
        new_obs = observe(result, result.observation.first)
        t3 = clock()
        if result.observation.first:
            history.clear()
        else:
            history.push(obs, result.applied_action, result.observation.reward, new_obs)
        obs = new_obs
        parts['estimator'] += t1 - t0 + clock() - t3
        parts['policy'] += t2 - t1
        parts['sim_bridge'] += t3 - t2
    elapsed, cpu = clock() - start, time.process_time() - cpu
    task.close()
    return steps / elapsed, cpu / steps * 1e3, {k: v / steps * 1e3 for k, v in parts.items()}


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (from /proc; all its threads)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def rss_mb(pid: int) -> float:
    """Resident memory of a process in MiB (from /proc)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024
    return float('nan')


def segment_times(sent: dict[str, dict[int, int]]) -> dict[str, float]:
    """p50 / p99 / mean ms of each SEGMENTS part over the steps seen on all three topics.

    `sent`: per topic ('feedback', 'context', 'action'), step -> source timestamp (ns). A step
    k whose k + 1 is the next episode's first still counts: sim_bridge's reset is its work.
    """
    feedback, context, action = sent['feedback'], sent['context'], sent['action']
    steps = [k for k in sorted(feedback) if k in context and k in action and k + 1 in feedback]
    parts = {'estimator': [context[k] - feedback[k] for k in steps],
             'policy': [action[k] - context[k] for k in steps],
             'sim_bridge': [feedback[k + 1] - action[k] for k in steps]}
    out: dict[str, float] = {}
    for name, values in parts.items():
        ms = np.asarray(values, float) * 1e-6
        out.update({f'seg_{name}_p50': float(np.percentile(ms, 50)) if len(ms) else math.nan,
                    f'seg_{name}_p99': float(np.percentile(ms, 99)) if len(ms) else math.nan,
                    f'seg_{name}_mean': float(ms.mean()) if len(ms) else math.nan})
    return out


def bridge_latency(log: str) -> dict[str, float]:
    """p50 / p99 ms of sim_bridge's own count in its log (nan where the run never said it)."""
    from zeus_ros.nodes.meters import SUMMARY

    found = SUMMARY.findall(log)
    p50, p99 = (float(found[-1][0]), float(found[-1][1])) if found else (math.nan, math.nan)
    return {'p50_bridge': p50, 'p99_bridge': p99}


def live_rate(checkpoint: Path, steps: int, pixels: bool, mode: str = 'multi',
              executor: str | None = None, context_lag: int = 0, split: bool = False
              ) -> dict[str, float]:
    """Steps/s, latency percentiles and node memory of the three-node lockstep loop.

    `mode` (MODES): a process per node, or the three nodes in one process on one executor
    (zeus launch --single-process) with or without intra-process delivery. `executor`: the
    nodes' $ZEUS_EXECUTOR (None: as this process's environment says). `context_lag`: the
    policy's parameter of that name. `split`: also the step's segments (SEGMENTS,
    `segment_times`), from a probe subscription to the context topic.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from zeus_msgs.msg import Action, ContextEstimate, StepFeedback

    from zeus_ros.nodes.spin import EXECUTOR_ENV
    from zeus_ros.nodes.topics import TOPICS, step_qos
    from zeus_ros.system.launch_defaults import (
        CONTAINER,
        CONTAINER_MODULE,
        CONTAINER_NO_INTRA,
        NODES,
    )
    from zeus_ros.system.processes import ros_env

    env = ros_env()  # $ROS_DOMAIN_ID, else one from $ZEUS_DOMAIN_RANGE; loopback only
    if executor is not None:
        env[EXECUTOR_ENV] = executor
    domain = int(env['ROS_DOMAIN_ID'])
    values = '[' + ','.join(str(v) for v in SCHEDULE['values']) + ']'
    quiet = mode == 'single-quiet'
    params = {
        'context_estimator': [f'checkpoint:={checkpoint}'],
        'policy': [f'checkpoint:={checkpoint}', f'context_lag:={context_lag}'],
        'sim_bridge': [f'task:={TASK}', f'max_steps:={steps}',
                       f'pixels:={"true" if pixels else "false"}', 'schedule.kind:=switch',
                       'schedule.every:=100', f'schedule.values:={values}',
                       f'min_observers:={2 if quiet else 3}'],
    }
    ros_args = {name: ['--ros-args', *(a for v in values for a in ('-p', v))]
                for name, values in params.items()}
    single = mode not in ('multi', 'pair')
    if single:
        switch = [CONTAINER_NO_INTRA] if mode == 'single-dds' else []
        argvs = {CONTAINER: [sys.executable, '-m', CONTAINER_MODULE, *switch, *(
            a for name, args in ros_args.items() for a in ('--node', name, *args))]}
    elif mode == 'pair':
        argvs = {CONTAINER: [sys.executable, '-m', CONTAINER_MODULE, *(
            a for name, args in ros_args.items() if name != 'sim_bridge'
            for a in ('--node', name, *args))],
            'sim_bridge': [sys.executable, '-m', NODES['sim_bridge'], *ros_args['sim_bridge']]}
    else:
        argvs = {name: [sys.executable, '-m', NODES[name], *args]
                 for name, args in ros_args.items()}
    loop = CONTAINER if single else 'sim_bridge'
    log_dir = Path(tempfile.gettempdir()) / 'zeus_bench_logs'
    log_dir.mkdir(exist_ok=True)
    processes = {name: subprocess.Popen(argv, env=env, stdout=(log_dir / f'{name}.log').open('w'),
                                        stderr=subprocess.STDOUT, start_new_session=True)
                 for name, argv in argvs.items()}
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    probe = rclpy.create_node('bench_probe', context=context)
    seen_obs: dict[int, float] = {}  # step: the probe's clock when its callback ran
    seen_act: dict[int, float] = {}
    sent_obs: dict[int, int] = {}  # step: source timestamp (ns), stamped by the publisher
    sent_act: dict[int, int] = {}
    sent_ctx: dict[int, int] = {}

    def observer(seen: dict[int, float], sent: dict[int, int]) -> Any:
        def on_message(msg: Any, info: Any) -> None:  # two parameters: rclpy adds MessageInfo
            seen.setdefault(msg.step, time.perf_counter())
            sent.setdefault(msg.step, info['source_timestamp'])
        return on_message
    counted: list[tuple[float, int, float]] = []  # single-quiet: time, steps so far, CPU s

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('sim_bridge: step loop'):
                steps_so_far = int({kv.key: kv.value for kv in status.values}['steps'])
                counted.append((time.perf_counter(), steps_so_far,
                                sum(cpu_seconds(p.pid) for p in processes.values())))

    if quiet:
        probe.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 50)
    else:
        probe.create_subscription(StepFeedback, TOPICS.STEP, observer(seen_obs, sent_obs),
                                  step_qos(50))
        probe.create_subscription(Action, TOPICS.ACTION, observer(seen_act, sent_act),
                                  step_qos(50))
        if split:
            probe.create_subscription(ContextEstimate, TOPICS.CONTEXT, observer({}, sent_ctx),
                                      step_qos(50))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    memory: dict[str, float] = {}
    cpu: list[tuple[int, dict[str, float]]] = []  # (steps seen, CPU seconds per process)
    try:
        deadline = time.monotonic() + 500
        while processes[loop].poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
            if max(len(seen_obs), counted[-1][1] if counted else 0) >= steps // 2 and not memory:
                memory = {name: rss_mb(p.pid) for name, p in processes.items()}
            # CPU per step between 10 % and 90 % of the run: load on the machine stretches
            # the wall clock, not the work a step costs.
            if len(cpu) < 2 and len(seen_obs) >= steps * (1 + 8 * len(cpu)) // 10:
                cpu.append((len(seen_obs), {name: cpu_seconds(p.pid)
                                            for name, p in processes.items()}))
    finally:
        for process in processes.values():
            process.terminate()
        for process in processes.values():
            process.wait(timeout=20)
        executor.shutdown()
        probe.destroy_node()
        rclpy.shutdown(context=context)
    memory_values = {f'rss_{k}': v for k, v in memory.items()}
    bridge = bridge_latency((log_dir / f'{loop}.log').read_text())
    if quiet:  # between the first and the last count taken while the loop ran
        running = [entry for entry in counted if 0 < entry[1] < steps]
        if len(running) < 2:
            raise RuntimeError(f'sim_bridge reported its steps {len(running)} time(s) while '
                               f'running {steps} steps: raise QUIET_SECONDS; node logs in '
                               f'{log_dir}')
        (t0, n0, c0), (t1, n1, c1) = running[0], running[-1]
        return {'rate': (n1 - n0) / (t1 - t0), 'cpu_ms': (c1 - c0) / (n1 - n0) * 1e3,
                'p50': bridge['p50_bridge'], 'p99': bridge['p99_bridge'],
                'p99_seen': float('nan'), **bridge, **memory_values}
    done = sorted(set(seen_obs) & set(seen_act))
    if len(done) < 20:
        raise RuntimeError(f'only {len(done)} steps completed; node logs in {log_dir}')
    per_process = {name: (cpu[1][1][name] - cpu[0][1][name]) / (cpu[1][0] - cpu[0][0]) * 1e3
                   for name in processes} if len(cpu) == 2 else {}
    cpu_ms = sum(per_process.values()) if per_process else float('nan')
    latency = np.array([(sent_act[k] - sent_obs[k]) * 1e-6 for k in done])
    latency_seen = np.array([(seen_act[k] - seen_obs[k]) * 1e3 for k in done])
    span = seen_obs[done[-1]] - seen_obs[done[0]]
    return {'rate': (len(done) - 1) / span, 'cpu_ms': cpu_ms,
            'p50': float(np.percentile(latency, 50)),
            'p99': float(np.percentile(latency, 99)),
            'p99_seen': float(np.percentile(latency_seen, 99)), **bridge, **memory_values,
            **{f'cpu_{name}': ms for name, ms in per_process.items()},
            **(segment_times({'feedback': sent_obs, 'context': sent_ctx, 'action': sent_act})
               if split else {})}


MODES = ('multi', 'pair', 'single', 'single-dds', 'single-quiet')
RATIO_TARGETS = {('state', 'multi'): 0.5, ('state', 'pair'): 0.5, ('state', 'single'): 0.8,
                 ('state', 'single-dds'): 0.8, ('state', 'single-quiet'): 0.8,
                 ('pixels', 'multi'): 0.9, ('pixels', 'pair'): 0.9, ('pixels', 'single'): 0.9,
                 ('pixels', 'single-dds'): 0.9, ('pixels', 'single-quiet'): 0.9}
"""Issue 14's targets: live steps/s over the in-process loop's (pixels: the render-bound rate)."""
P99_TARGETS_MS = {'state': 2.0, 'pixels': 10.0}
"""Issue 14's observation -> action p99 targets."""
QUIET_SECONDS = 10.0
"""single-quiet runs this long at the in-process rate: sim_bridge counts its steps on
/diagnostics once a second, and the rate needs two counts taken while the loop runs."""


def quiet_steps(steps: int, in_process_rate: float) -> int:
    """Steps of a single-quiet run: about QUIET_SECONDS at the round's in-process rate.

    Why not a fixed multiple of --steps: at ~1200 steps/s, 10x400 steps ended in ~3 s, before
    sim_bridge had reported its count twice. The live loop is no faster than the in-process
    one (ratio targets <= 1), so it runs at least this long; --steps stays the floor.
    """
    return max(steps, math.ceil(in_process_rate * QUIET_SECONDS))


def lag_summary(results: list[dict], lags: list[int]) -> list[str]:
    """Per kind, mode and executor: each lag's paired difference to lag 0, round by round."""
    lines = []
    for kind, mode, executor, lag in dict.fromkeys(
            (r['kind'], r['mode'], r['executor'], r['lag']) for r in results):
        if lag == 0 or 0 not in lags:
            continue
        rounds = {(r['round'], r['lag']): r for r in results
                  if (r['kind'], r['mode'], r['executor']) == (kind, mode, executor)}
        paired = [n for n, other in rounds if other == lag and (n, 0) in rounds]
        if len(paired) < 2:
            continue
        parts = []
        for metric in ('rate', 'ratio', 'cpu_ms', 'p50', 'p99', 'p99_seen', 'p99_bridge'):
            diffs = np.array([rounds[n, lag][metric] - rounds[n, 0][metric] for n in paired])
            error = diffs.std(ddof=1) / np.sqrt(len(diffs))
            parts.append(f'{metric} {diffs.mean():+.3f} ± {error:.3f}')
        lines.append(f'{kind} {mode}/lag{lag} - {mode} ({executor}, {len(paired)} paired rounds): '
                     + ', '.join(parts))
    return lines


def main() -> None:
    """Measure state and pixel loops, multi- and single-process, and print one table."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--steps', type=int, default=400)
    parser.add_argument('--pixel-steps', type=int, default=120)
    parser.add_argument('--modes', default='multi,single,single-dds,single-quiet',
                        help='multi: a process per node; pair: sim_bridge alone, estimator '
                        'and policy in one container; single: one process, one executor, '
                        'intra-process delivery; single-dds: the same through DDS; '
                        'single-quiet: single with no outside subscriber (rate only)')
    parser.add_argument('--kinds', default='state,pixels', help='observation kinds to run')
    parser.add_argument('--repeat', type=int, default=1,
                        help='rounds of in-process + every mode (A/B on a loaded machine)')
    parser.add_argument('--executors', default='',
                        help='executors the nodes spin on, each mode run once per executor '
                        'in every round (e.g. single,events; default: as $ZEUS_EXECUTOR says)')
    parser.add_argument('--context-lags', default='0',
                        help='policy context_lag values, each mode run once per value in every '
                        'round (e.g. 0,1)')
    parser.add_argument('--out', type=Path,
                        help='also write every row to OUT/live_loop.csv, the targets to '
                        'OUT/live_loop_targets.png and, with --split, the segments beside the '
                        'in-process parts to OUT/live_loop_split.png')
    parser.add_argument('--split', action='store_true',
                        help="split each step's period into the estimator's, the policy's and "
                        "sim_bridge's segments (publishers' timestamps; one more reader of the "
                        'context topic)')
    args = parser.parse_args()
    from zeus_ros.nodes.spin import EXECUTORS, executor_kind

    modes = [m.strip() for m in args.modes.split(',') if m.strip()]
    kinds = [k.strip() for k in args.kinds.split(',') if k.strip()]
    executors = [e.strip() for e in args.executors.split(',') if e.strip()]
    try:
        lags = [int(v) for v in args.context_lags.split(',') if v.strip()]
    except ValueError:
        parser.error(f'--context-lags {args.context_lags!r}: give integers, e.g. 0,1')
    if not lags or min(lags) < 0:
        parser.error(f'--context-lags {args.context_lags!r}: give integers >= 0, e.g. 0,1')
    unknown = [m for m in modes if m not in MODES] + [k for k in kinds if k not in P99_TARGETS_MS]
    unknown += [e for e in executors if e not in EXECUTORS]
    if unknown:
        parser.error(f'unknown mode, kind or executor {", ".join(unknown)}: modes are '
                     f'{", ".join(MODES)}, kinds {", ".join(P99_TARGETS_MS)}, executors '
                     f'{", ".join(EXECUTORS)}')
    try:
        executors = executors or [executor_kind()]
    except ValueError as error:
        parser.error(str(error))
    print(f'three-node lockstep loop vs in-process loop, {TASK} (targets in brackets; '
          'in-process = ScheduledEnv + the deployment code, no ROS)')
    print(f'{"obs":<7} {"mode":<10} {"executor":<8} {"in-proc/s":>9} {"live/s":>8} '
          f'{"ratio [target]":>15} {"CPU ms/step":>13} {"CPU ratio":>9} {"p50 ms":>7} '
          f'{"p99 ms [target]":>16} {"p99 seen":>8} {"p99 bridge":>10}  '
          'RSS MiB per process; CPU ms per step per process')
    results: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            steps = args.steps if kind == 'state' else args.pixel_steps
            checkpoint = make_checkpoint(Path(tmp) / f'{kind}.pt', kind)
            runs = [(mode, executor, lag) for mode in modes for executor in executors
                    for lag in lags]
            # Every other round runs its modes in reverse: a machine speeding up or slowing
            # down during the run favours neither side of a comparison.
            for number, mode, executor, lag in [
                    (n, *run) for n in range(args.repeat)
                    for run in [(None, None, 0), *(runs[::-1] if n % 2 else runs)]]:
                if mode is None:  # each round against its own in-process rate
                    local, local_cpu, local_parts = in_process_rate(checkpoint, steps)
                    continue
                run_steps = quiet_steps(steps, local) if mode == 'single-quiet' else steps
                live = live_rate(checkpoint, run_steps, pixels=kind == 'pixels', mode=mode,
                                 executor=executor, context_lag=lag,
                                 split=args.split and mode != 'single-quiet')
                ratio, target = live['rate'] / local, RATIO_TARGETS[kind, mode]
                results.append({'kind': kind, 'mode': mode, 'executor': executor, 'lag': lag,
                                'round': number, 'ratio': ratio, 'in_process_rate': local,
                                'in_process_cpu_ms': local_cpu, **live,
                                **{f'in_process_{k}_mean': v for k, v in local_parts.items()}})
                p99_target = P99_TARGETS_MS[kind]
                memory = ' '.join(f'{k[4:]} {v:.0f}' for k, v in live.items()
                                  if k.startswith('rss_'))
                per_node = ' '.join(f'{k[4:]} {v:.2f}' for k, v in live.items()
                                    if k.startswith('cpu_') and k != 'cpu_ms')
                ratio_text = f'{ratio:.3f} [{target}]' + ('' if ratio >= target else '!')
                p99_text = f'{live["p99"]:.2f} [{p99_target}]' + (
                    '' if live['p99'] <= p99_target or np.isnan(live['p99']) else '!')
                cpu_text = f'{local_cpu:.2f}/{live["cpu_ms"]:.2f}'
                label = f'{mode}/lag{lag}' if lag else mode
                print(f'{kind:<7} {label:<10} {executor:<8} {local:>9.1f} {live["rate"]:>8.1f} '
                      f'{ratio_text:>15} {cpu_text:>13} {local_cpu / live["cpu_ms"]:>9.3f} '
                      f'{live["p50"]:>7.2f} {p99_text:>16} {live["p99_seen"]:>8.2f} '
                      f'{live["p99_bridge"]:>10.2f}  {memory}'
                      + (f'; CPU {per_node}' if per_node else ''), flush=True)
                if 'seg_policy_p50' in live:
                    print(f'{"":<7} {"":<10} split, ms p50 / p99 / mean (in-process): '
                          + ', '.join(
                        f'{name} {live[f"seg_{name}_p50"]:.2f} / {live[f"seg_{name}_p99"]:.2f}'
                        f' / {live[f"seg_{name}_mean"]:.2f} ({local_parts[name]:.2f})'
                        for name in SEGMENTS) + f'; period {1e3 / live["rate"]:.2f} '
                        f'({1e3 / local:.2f})', flush=True)
    for line in lag_summary(results, lags):
        print(line)
    if args.out is not None:
        from live_loop_plot import plot_segments, plot_targets, write_rows

        args.out.mkdir(parents=True, exist_ok=True)
        write_rows(results, args.out / 'live_loop.csv')
        plot_targets(results, RATIO_TARGETS, P99_TARGETS_MS, args.out / 'live_loop_targets.png')
        print(f'rows: {args.out / "live_loop.csv"}; targets: {args.out / "live_loop_targets.png"}')
        if any('seg_policy_mean' in row for row in results):
            plot_segments(results, SEGMENTS, args.out / 'live_loop_split.png')
            print(f'split: {args.out / "live_loop_split.png"}')
    print("p50/p99: observation -> action from the publishers' source timestamps (single-quiet: "
          "sim_bridge's own, as p99 bridge); p99 seen: from the probe's callback times (adds its "
          "wake-ups); p99 bridge: sim_bridge's own measure over the run, StepFeedback k published "
          "to Action k received (the action's way back included; no reader of the loop needed)")
    print("! marks a target not met. CPU ms/step: in-process / live (all the loop's processes, "
          'DDS threads included, 10-90 % of the run); CPU ratio = in-process / live: the rate '
          'ratio an idle machine would show, as far as the loop is CPU-bound; steadier than '
          'the wall-clock ratio on a loaded machine')


if __name__ == '__main__':
    main()
