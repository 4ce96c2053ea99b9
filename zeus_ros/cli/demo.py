"""The live demo: the full system while the physics changes unannounced (default Cheetah-Bias-v0).

sim_bridge switches the context (a constant torque bias on every motor by default; --task picks
another family) in the middle of episodes, between training and beyond-range values;
context_estimator and policy run the family's zoo checkpoint (params/tasks/<Task>.yaml names it,
checkpoints/README.md lists them); this process watches the topics (subscribe only, like
`zeus inspect`), prints the live view and the per-segment summary, and saves the inspection
figure and per-step CSV under --out.

Then it runs the same schedule again with the policy's context FROZEN at the mean context the
policy infers on its training values (stored in the zoo checkpoint; policy parameter
frozen_context) and prints the per-segment returns side by side: the value of adaptation,
live. With --seeds N it does both for N schedule seeds (other initial states, the same
switches) and reports the paired difference with its standard error, split into training and
beyond-range values (value_of_adaptation.csv / .png). `--no-frozen` skips the frozen runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
import os
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

from sim_bridge.registry import TASK_NAMES
from zeus_ros.cli.demo_summary import (
    adaptation_rows,
    plot_adaptation,
    summarize_adaptation,
    write_rows,
)
from zeus_ros.cli.inspect_topics import Inspector
from zeus_ros.cli.launch import NodeProcess, Supervisor, node_argv
from zeus_ros.cli_args import (
    EXPECT_SHA256_HELP,
    ZeusArgumentParser,
    at_least,
    seed_arg,
    sha256_arg,
)
from zeus_ros.step_log import format_segments, percentile, plot_inspection
from zeus_ros.system.launch_defaults import (
    RECORDED_ANSWERS,
    pixel_checkpoint,
    start_args,
    zoo_checkpoint,
)
from zeus_ros.system.processes import group_domain_id, ros_env

DEFAULT_TASK = 'Cheetah-Bias-v0'
"""The demo's family: physics that changes (a motor bias), where the zoo's ZeUS policy reads its
context and beyond the training range takes the oracle's headroom (docs/results.md)."""


def default_checkpoint(task: str = DEFAULT_TASK) -> Path:
    """The family's zoo checkpoint (ValueError when the family has none)."""
    return zoo_checkpoint(task)


def schedule_values(task: str) -> list[float] | str:
    """Context values the demo cycles through (the family's `demo:` declaration)."""
    from sim_bridge.families import family

    return family(task).demo_schedule()[1]


def schedule_lengths(task: str) -> tuple[int, int]:
    """(steps between switches, steps of the run): 10 switches' worth of the family's schedule.

    Short episodes (the 40-step cheetah families): a switch mid-episode, 10 episodes. Long
    ones: every 150 steps, 2000 steps.
    """
    from sim_bridge.families import family

    every = family(task).demo_schedule()[0]
    return every, (20 * every if every < 150 else 2000)


VIEWER = 'zeus_demo_view'
"""The demo's own inspector node: one of the group sim_bridge waits for by name."""


def demo_group(args: argparse.Namespace, checkpoint: Path | None) -> list[str]:
    """The nodes the demo starts (its viewer not included)."""
    return ['sim_bridge', *(['context_estimator'] if checkpoint is not None else []),
            'policy', *(['recorder'] if args.record else [])]


def viewer_expects(group: Sequence[str]) -> list[str]:
    """The topics whose publishers the viewer must hear before it takes the steps."""
    from zeus_ros.nodes.topics import TOPICS

    answers = [topic.lstrip('/') for node, topic in RECORDED_ANSWERS.items() if node in group]
    return [*answers, TOPICS.CONTEXT_TRUTH]


def build_nodes(args: argparse.Namespace, checkpoint: Path | None,
                frozen: str = '') -> list[NodeProcess]:
    """The node processes of the demo with their parameters (`frozen`: policy frozen_context)."""
    schedule = schedule_values(args.task)
    values = schedule if isinstance(schedule, str) else (
        '[' + ','.join(f'{float(v)}' for v in schedule) + ']')
    bridge = ['-p', f'task:={args.task}', '-p', f'max_steps:={args.steps}',
              '-p', f'pixels:={str(args.pixels).lower()}',
              '-p', f'seed:={args.seed}', '-p', 'schedule.kind:=switch',
              '-p', f'schedule.every:={args.every}', '-p', f'schedule.values:={values}']
    group = demo_group(args, checkpoint)

    def gates(name: str) -> list[str]:  # the step source waits for the viewer too
        return start_args(name, [*group, VIEWER])

    nodes = [NodeProcess('sim_bridge', node_argv('sim_bridge', None,
                                                 bridge + gates('sim_bridge')))]
    if checkpoint is not None:
        ckpt = ['-p', f'checkpoint:={checkpoint}', '-p', f'task:={args.task}']
        nodes.append(NodeProcess('context_estimator', node_argv(
            'context_estimator', None, ckpt + gates('context_estimator'))))
        frozen_param = ['-p', f'frozen_context:={frozen}'] if frozen else []
        nodes.append(NodeProcess('policy', node_argv(
            'policy', None, ckpt + frozen_param + gates('policy'))))
    else:
        nodes.append(NodeProcess('policy', node_argv(
            'policy', None, ['-p', f'task:={args.task}', '-p', f'seed:={args.seed}',
                             *gates('policy')])))
    if args.record:
        nodes.append(NodeProcess('recorder', node_argv(
            'recorder', None, ['-p', f'output:={args.out / "bag"}',
                               *gates('recorder')])))
    return nodes


def main(argv: list[str] | None = None) -> int:
    """Run the demo; exit code 1 if a node died."""
    parser = ZeusArgumentParser(prog='zeus demo', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--task', choices=TASK_NAMES, default=DEFAULT_TASK,
                        help='task family (default: %(default)s); its zoo checkpoint unless '
                        '--checkpoint (checkpoints/README.md lists the families that have one)')
    parser.add_argument('--checkpoint', type=Path, default=None,
                        help="default: the family's zoo checkpoint")
    parser.add_argument('--expect-sha256', type=sha256_arg, metavar='SHA256',
                        help=EXPECT_SHA256_HELP)
    parser.add_argument('--obs', choices=('state', 'pixels'), default='state',
                        help="pixels: sim_bridge renders 84x84 frames and the family's zoo "
                        'pixel checkpoint acts on them (experimental; about 20 steps/s on '
                        'this CPU)')
    parser.add_argument('--random-policy', action='store_true',
                        help='no checkpoint: a uniform-random policy and no estimator')
    parser.add_argument('--steps', type=at_least(1),
                        help='control steps per run (default 400 for 40-step episodes, else 2000)')
    parser.add_argument('--every', type=at_least(1),
                        help="steps between switches (default: the family's demo schedule)")
    parser.add_argument('--seed', type=seed_arg, default=0, help='first schedule seed')
    parser.add_argument('--seeds', type=at_least(1), default=3,
                        help='schedule seeds, each run live and frozen (paired; default 3)')
    parser.add_argument('--record', action='store_true', help='also record a bag under --out')
    parser.add_argument('--out', type=Path, default=Path('out/demo'))
    parser.add_argument('--no-frozen', action='store_true',
                        help='skip the runs with the context frozen')
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f'--seeds {args.seeds}: give at least 1')
    every, steps = schedule_lengths(args.task)
    args.every = every if args.every is None else args.every
    args.steps = steps if args.steps is None else args.steps
    checkpoint, args.pixels = None, args.obs == 'pixels'
    if not args.random_policy:
        try:
            checkpoint = (args.checkpoint or (pixel_checkpoint(args.task) if args.obs == 'pixels'
                                              else default_checkpoint(args.task))).resolve()
        except ValueError as error:
            print(f'zeus demo: --task {args.task}: {error} (--checkpoint FILE) or pass '
                  '--random-policy', file=sys.stderr)
            return 2
    if checkpoint is not None and not checkpoint.is_file():
        print(f'zeus demo: checkpoint {checkpoint} not found; train one (docs/training.md) or '
              'pass --random-policy', file=sys.stderr)
        return 2
    if checkpoint is not None:
        from zeus_ros.learning.checkpoint import load_checkpoint
        from zeus_ros.learning.errors import CheckpointError

        try:  # before any node starts or any file is written: a bad file leaves no results
            loaded = load_checkpoint(checkpoint, expect_task=args.task, load_optimizers=False,
                                     expect_sha256=args.expect_sha256)
        except CheckpointError as error:
            print(f'zeus demo: --checkpoint: {error}', file=sys.stderr)
            return 2
        args.pixels = loaded.spec.obs_kind == 'pixels'  # its frames, whatever --obs said
        checkpoint = with_readout(checkpoint, args.out)
    domain = group_domain_id()
    env = ros_env(domain)
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    args.out.mkdir(parents=True, exist_ok=True)
    print(f'[demo] {args.task}, context switching every {args.every} steps through '
          f'{schedule_values(args.task)}; policy: {checkpoint or "random"}; '
          f'ROS_DOMAIN_ID={domain}', flush=True)
    frozen = ''
    if checkpoint is not None and not args.no_frozen:
        frozen = frozen_context(checkpoint)
    rows: list[Any] = []
    names: tuple[str, ...] = ()
    first_seed = args.seed
    for index in range(args.seeds):
        args.seed = first_seed + index
        out = args.out if index == 0 else args.out / f'seed_{args.seed}'
        log, failed = _run(args, checkpoint, env, out,
                           label=f'context live, schedule seed {args.seed}')
        if failed is not None or not frozen:
            break
        names = log.context_names
        print(f"\n[demo] the same schedule again, the policy's context FROZEN at its "
              f'training mean (schedule seed {args.seed})', flush=True)
        frozen_log, failed = _run(args, checkpoint, env, out / 'frozen',
                                  label=f'context frozen, schedule seed {args.seed}',
                                  frozen=frozen, reference=log.segments())
        if failed is not None:
            break
        print('\n[demo] value of adaptation: per-segment return with the context live '
              f'and frozen (schedule seed {args.seed})')
        print(format_comparison(log.segments(), frozen_log.segments(), names))
        rows += adaptation_rows(args.seed, log.segments(), frozen_log.segments(),
                                train_values(args.task), min_steps=args.every)
    if rows:
        summary, sentence = summarize_adaptation(rows, args.every)
        write_rows(rows, names, args.out / 'value_of_adaptation.csv')
        figure = plot_adaptation(rows, names, args.out / 'value_of_adaptation.png',
                                 f'zeus demo {args.task}: context live - frozen, '
                                 f'{len(summary["seeds"])} schedule seed(s)')
        print(f'\n[demo] {sentence}\n[demo] per seed (whole run): '
              + ', '.join(f'{t:+.1f}' for t in summary['seed_totals'])
              + f'\n[demo] table {args.out / "value_of_adaptation.csv"}, figure {figure}')
    if failed == ('demo', 130):
        return 130
    if failed is not None:
        print(f'[demo] node {failed[0]!r} died with exit code {failed[1]}', file=sys.stderr)
        return 1
    return 0


def train_values(task: str) -> list[tuple[float, ...]]:
    """The family's training values (segments on them count as 'training values')."""
    from sim_bridge.families import family

    return [tuple(value.values()) for value in family(task).preset('train')]


def frozen_context(checkpoint: Path) -> str:
    """The policy parameter frozen_context: the checkpoint's training-mean context.

    Stored in zoo checkpoints (scripts/build_zoo.py); for another checkpoint it is measured
    now on the train values (deterministic episodes), never on the demo's own run.
    """
    from zeus_ros.learning.readout import stored_train_mean

    mean = stored_train_mean(checkpoint.read_bytes())
    if mean is None:
        from zeus_ros.learning.inference import InferenceAgent
        from zeus_ros.offline.evaluation.evaluate import train_mean_context

        print(f'[demo] measuring the training-mean context of {checkpoint.name} on its train '
              'values (3 episodes each) ...', flush=True)
        mean = train_mean_context(InferenceAgent.from_checkpoint(checkpoint), episodes=3,
                                  seed=200)
    if mean is None:
        return ''
    return ','.join(f'{v:.6g}' for v in np.asarray(mean).ravel())


def with_readout(checkpoint: Path, out: Path, steps: int = 1000) -> Path:
    """The checkpoint to deploy, with a context read-out.

    Itself when it holds one, else a copy in `out` with one calibrated now on its train
    contexts (never on the demo's own run).
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.learning.methods import method_objective
    from zeus_ros.learning.readout import readout_from_checkpoint_bytes, store_readout
    from zeus_ros.offline.evaluation.calibrate import calibrate_readout

    if readout_from_checkpoint_bytes(checkpoint.read_bytes()) is not None:
        return checkpoint
    agent = InferenceAgent.from_checkpoint(checkpoint)
    if agent.obs_kind != 'state' or method_objective(agent.method).context_source != 'psi':
        return checkpoint
    print(f'[demo] calibrating a context read-out for {checkpoint.name} on {steps} steps of its '
          'train contexts (psi -> context units) ...', flush=True)
    readout, novelty = calibrate_readout(agent, steps=steps)
    print(f'[demo] {readout.describe()}\n[demo] {novelty.describe()}', flush=True)
    return store_readout(checkpoint, readout, out / 'checkpoint_with_readout.pt', novelty)


def running_adaptation(log: Any, reference: Sequence[Any]) -> str:
    """'value of adaptation so far: ...' over the segments both runs finished ('' without)."""
    if not reference:
        return ''
    live = {s.segment: s for s in reference}
    done = log.segments()[:-1]  # the newest segment is still running
    gains = [live[s.segment].total_return - s.total_return for s in done
             if s.segment in live and live[s.segment].steps == s.steps]
    if not gains:
        return ''
    return (f'\n          value of adaptation so far: live - frozen {sum(gains):+.1f} over '
            f'{len(gains)} segments ({np.mean(gains):+.1f} per segment)')


def format_comparison(live: list[Any], frozen: list[Any], names: Sequence[str]) -> str:
    """Side-by-side per-segment returns of the live and the frozen run, and their sum."""
    header = (f'{"seg":>4} {"context":<28} {"live":>9} {"frozen":>9} {"live - frozen":>14}')
    lines = [header, '-' * len(header)]
    totals = [0.0, 0.0]
    frozen_by_segment = {s.segment: s for s in frozen}
    for seg in live:
        other = frozen_by_segment.get(seg.segment)
        if other is None or other.steps != seg.steps:
            continue  # a segment cut short in one of the runs is not comparable
        context = ', '.join(f'{n}={v:g}' for n, v in zip(names, seg.context, strict=False))
        totals[0] += seg.total_return
        totals[1] += other.total_return
        lines.append(f'{seg.segment:>4} {context:<28} {seg.total_return:>9.2f} '
                     f'{other.total_return:>9.2f} {seg.total_return - other.total_return:>14.2f}')
    lines.append('-' * len(header))
    lines.append(f'{"all":>4} {"":<28} {totals[0]:>9.2f} {totals[1]:>9.2f} '
                 f'{totals[0] - totals[1]:>14.2f}')
    return '\n'.join(lines)


def _run(args: argparse.Namespace, checkpoint: Path | None, env: dict[str, str], out: Path,
         *, label: str, frozen: str = '', reference: Sequence[Any] = ()
         ) -> tuple[Any, tuple[str, int] | None]:
    """One run of the system; prints live views and the summary, writes CSV and figure.

    `reference`: the live run's segments; the view then adds the running value of adaptation
    over the segments this run has finished.
    """
    out.mkdir(parents=True, exist_ok=True)
    inspector = Inspector(name=VIEWER, expect=viewer_expects(demo_group(args, checkpoint)))
    supervisor = Supervisor(build_nodes(args, checkpoint, frozen), env)
    started = time.monotonic()
    supervisor.start()
    failed: tuple[str, int] | None = None
    try:
        next_draw = time.monotonic() + 5.0
        while True:
            inspector.executor.spin_once(timeout_sec=0.02)
            name, code = supervisor.wait(timeout=0)
            if name is not None:
                if code != 0:
                    failed = (name, code)
                # drain what is still in flight
                drain_until = time.monotonic() + 1.0
                while time.monotonic() < drain_until:
                    inspector.executor.spin_once(timeout_sec=0.02)
                break
            if time.monotonic() >= next_draw and inspector.current() is not None:
                print(inspector.view() + running_adaptation(inspector.log, reference),
                      flush=True)
                next_draw = time.monotonic() + 5.0
    except KeyboardInterrupt:
        print('[demo] Ctrl-C: stopping', flush=True)
        failed = ('demo', 130)
    finally:
        supervisor.stop()
        inspector.close()
    wall = time.monotonic() - started
    log = inspector.log
    print(f'\n[demo] {label}: per-segment summary (return = sum of rewards while that '
          'context was in force)')
    print(format_segments(log.segments(), log.context_names))
    latency = log.latencies_ms()
    print(f'[demo] {len(log.records)} steps in {wall:.1f} s '
          f'({len(log.records) / max(wall, 1e-9):.1f} steps/s incl. start-up); '
          f'observation->action latency p50 {percentile(latency, 50):.2f} ms, '
          f'p99 {percentile(latency, 99):.2f} ms')
    print(f'[demo] per-step log: {log.save_csv(out / "steps.csv")}')
    print(f'[demo] figure: {plot_inspection(log, out / "inspection.png", f"zeus demo ({label})")}')
    return log, failed


if __name__ == '__main__':
    raise SystemExit(main())
