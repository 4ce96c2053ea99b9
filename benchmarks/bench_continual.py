"""Drift scenarios: the same run with and without `zeus launch --continual`, default settings.

Three scenarios where the zoo checkpoint's zero-shot adaptation fades (`--scenario`):
`bias` (Cheetah-Bias-v0, motor bias 0.6-0.9; the train range ends at 0.3), `motor`
(Cheetah-Motor-v0, motors stronger than any trained: gain 1.7-2.2; trained up to 1.15) and
`run` (Cheetah-Run-v1, target velocity 4.15-4.95 m/s; trained up to 3.0). The zoo checkpoint
is deployed while the context steps through the scenario's values, one per `--every` steps,
in realtime at `--rate` steps/s, for `--wall` seconds per mode; `--parallel` runs the modes
side by side (each on its own ROS domain from `--domain-range`), `--burners N` adds N busy
processes for the whole run (a loaded robot computer). The launches get the defaults a user
gets: nothing of the trainer's is set unless given here (`--new-steps`, `--tolerance`, ...).

Reported, per mode: return per context segment over time (reward per step x the 40-step
episode, from the recording), the trainer's swaps, refusals and rollbacks (its history), the
time from the first step to the first gate decision, its CPU share, and the loop's observation
-> action latency at p50/p99 with the trainer busy (inside a round) and idle. Afterwards, in
process, on seeds no gate used: the zoo checkpoint, its oracle and no_context references and
every checkpoint the continual run deployed, at the scenario's values and at the family's
train values (`references.csv`: the gap closed, and that nothing deployed lost more than the
gate's tolerance at a train value). Mode `drill`: --continual whose first round trains on
negated rewards and is forced past the gate, to show the live rollback. CSV + PNG in --out.

    python benchmarks/bench_continual.py --scenario bias --wall 1200 --parallel --out out/bias
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SCENARIOS: dict[str, tuple[str, str, list[float]]] = {
    'bias': ('Cheetah-Bias-v0', 'cheetah_bias_v0', [0.6, 0.7, 0.75, 0.8, 0.85, 0.9]),
    'motor': ('Cheetah-Motor-v0', 'cheetah_motor_v0', [1.7, 1.8, 1.9, 2.0, 2.1, 2.2]),
    'run': ('Cheetah-Run-v1', 'cheetah_run_v1', [4.15, 4.3, 4.5, 4.65, 4.8, 4.95]),
}
"""Scenario -> (task, zoo folder, context values beyond the train range). Where the zoo
checkpoint fades (issue 47): bias -98 per episode against the oracle's -40; motor below its
own no_context; run keeps 0.1-0.2 of the oracle's headroom."""
REFERENCE_SEED = 7000
"""In-process evaluation seeds of the references: no gate uses them (gates: 300 + 1000 r)."""
REFERENCE_EPISODES = 10


def _params(folder: Path, args: argparse.Namespace, mode: str) -> Path:
    params = yaml.safe_load((REPO / 'params' / 'zeus.yaml').read_text())
    task, zoo_folder, values = SCENARIOS[args.scenario]
    zoo = str(REPO / 'checkpoints' / zoo_folder / 'zeus.pt')
    bridge = params['/**/sim_bridge']['ros__parameters']
    bridge.update({'task': task, 'mode': 'realtime', 'control_rate': float(args.rate),
                   'schedule': {'kind': 'switch', 'every': args.every, 'values': values}})
    for node in ('context_estimator', 'policy'):
        params[f'/**/{node}']['ros__parameters']['checkpoint'] = zoo
    for section in params.values():  # every node that names the task runs the scenario's
        if isinstance(section, dict) and 'task' in section.get('ros__parameters', {}):
            section['ros__parameters']['task'] = task
    if args.noise is not None:
        params['/**/policy']['ros__parameters']['noise'] = args.noise
    recorder = params['/**/recorder']['ros__parameters']
    recorder['output'] = str(folder / 'rec')
    if args.split_s is not None:
        recorder['split_duration_s'] = args.split_s
    elif mode == 'fixed':
        recorder['split_duration_s'] = 20.0  # as --continual splits (launch_defaults)
    trainer = {key: value for key, value in (
        ('new_steps', args.new_steps), ('warmup_updates', args.warmup),
        ('updates', args.updates), ('bc_weight', args.bc_weight),
        ('tolerance', args.tolerance)) if value is not None}
    if mode == 'drill':
        trainer.update({'corrupt_rounds': [1], 'force_rounds': [1]})
    if trainer:
        params['/**/continual_trainer'] = {'ros__parameters': trainer}
    path = folder / 'params.yaml'
    path.write_text(yaml.safe_dump(params))
    return path


def _context_name(task: str) -> str:
    from sim_bridge.families import family

    return family(task).specs[0].name


def _cpu_seconds(pid: int) -> float:
    """The trainer's CPU seconds, its rounds' child processes (`zeus continual-round`) included.

    utime + stime + cutime + cstime (the finished rounds), plus the round running now.
    """
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    ticks = sum(int(fields[i]) for i in (11, 12, 13, 14))  # clock ticks
    with contextlib.suppress(OSError, ValueError):
        for child in Path(f'/proc/{pid}/task/{pid}/children').read_text().split():
            inner = Path(f'/proc/{child}/stat').read_text().rsplit(')', 1)[1].split()
            ticks += int(inner[11]) + int(inner[12])
    return ticks / 100.0


def _trainer_pid(root: int) -> int | None:
    for proc in Path('/proc').iterdir():
        if proc.name.isdigit():
            try:
                cmd = (proc / 'cmdline').read_bytes()
            except OSError:
                continue
            if b'continual_node' in cmd and _descends(int(proc.name), root):
                return int(proc.name)
    return None


def _descends(pid: int, root: int) -> bool:
    while pid > 1:
        if pid == root:
            return True
        try:
            pid = int(Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[1])
        except (OSError, ValueError):
            return False
    return False


def run_modes(modes: list[str], args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """One launch per mode for --wall seconds (side by side with --parallel, else in turn).

    Each launch has its own ROS domain from --domain-range (a test run on the same domain
    would write its steps into this run's recording); the trainer's CPU is sampled every 2 s.
    """
    from zeus_ros.system.processes import DOMAIN_RANGE_ENV, domain_range

    os.environ[DOMAIN_RANGE_ENV] = args.domain_range
    first, last = domain_range()
    domains = iter(np.random.default_rng().permutation(np.arange(first, last + 1)).tolist())
    burners = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                                start_new_session=True) for _ in range(args.burners)]
    try:
        batches = [modes] if args.parallel else [[mode] for mode in modes]
        infos: dict[str, dict[str, Any]] = {}
        for batch in batches:
            runs = [_start(mode, args.out / mode, args, int(next(domains))) for mode in batch]
            try:
                while any(run['launch'].poll() is None for run in runs):
                    time.sleep(2)
                    for run in runs:
                        _sample_cpu(run)
            except KeyboardInterrupt:
                for run in runs:
                    run['launch'].send_signal(signal.SIGINT)
            for run in runs:
                run['launch'].wait(timeout=120)
                run['log'].close()
                wall = time.monotonic() - run['begin']
                info = {'scenario': args.scenario, 'mode': run['mode'],
                        'domain': run['domain'], 'burners': args.burners, 'wall_s': wall,
                        'trainer_cpu_s': run['cpu'], 'trainer_share': run['cpu'] / wall}
                (args.out / run['mode'] / 'info.json').write_text(json.dumps(info))
                infos[run['mode']] = info
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    return infos


def _start(mode: str, folder: Path, args: argparse.Namespace, domain: int) -> dict[str, Any]:
    from zeus_ros.system.processes import ros_env

    if folder.exists():
        import shutil

        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    params = _params(folder, args, mode)
    argv = [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params', str(params), '--record',
            '--no-progress', '--timeout', str(args.wall)]
    argv += ['--continual'] if mode != 'fixed' else []
    log = (folder / 'launch.log').open('w')
    launch = subprocess.Popen(argv, env=ros_env(domain), stdout=log, stderr=subprocess.STDOUT,
                              cwd=folder, start_new_session=True)
    print(f'{mode}: launched on ROS domain {domain}, {args.wall:.0f} s ({folder})', flush=True)
    return {'mode': mode, 'launch': launch, 'log': log, 'begin': time.monotonic(),
            'cpu': 0.0, 'pid': None, 'domain': domain}


def _sample_cpu(run: dict[str, Any]) -> None:
    if run['mode'] == 'fixed' or run['launch'].poll() is not None:
        return
    run['pid'] = run['pid'] or _trainer_pid(run['launch'].pid)
    if run['pid'] is not None:
        with contextlib.suppress(OSError):
            run['cpu'] = _cpu_seconds(run['pid'])


def own_splits(folder: Path, task: str) -> list[Path]:
    """The run's closed splits that hold only its task's steps.

    The recorder, like `ros2 bag record`, records whatever is on its topics: a test run that
    landed on the same ROS domain left another task's steps in one split of a 30-minute run
    (the loop itself refused them: they were not its paired publishers). Such a split is left
    out and named.
    """
    from zeus_ros.bags.errors import IngestError
    from zeus_ros.bags.recording import closed_splits
    from zeus_ros.offline.data.ingest import ingest_bags

    kept = []
    for split in closed_splits(folder / 'rec'):
        try:
            found = ingest_bags([split]).task
        except IngestError as error:
            print(f'left out {split.name}: {error}', flush=True)
            continue
        if found == task:
            kept.append(split)
        else:
            print(f'left out {split.name}: steps of {found}', flush=True)
    return kept


def latencies(splits: list[Path]) -> list[tuple[float, float, int]]:
    """(state receive time [s, epoch], action - state receive time [ms], step) per step."""
    from rosbags.rosbag2 import Reader

    from zeus_ros.bags.recover import step_from_cdr
    from zeus_ros.bags.schema import TOPIC_ACTION, TOPIC_STATE

    seen: dict[str, dict[int, int]] = {TOPIC_STATE: {}, TOPIC_ACTION: {}}

    for bag in splits:
        reader = Reader(bag)
        reader.open()
        try:
            wanted = [c for c in reader.connections if c.topic in seen]
            for connection, stamp, raw in reader.messages(connections=wanted):
                step = step_from_cdr(raw)
                if step is not None:
                    seen[connection.topic].setdefault(step, stamp)
        finally:
            reader.close()
    state, action = seen[TOPIC_STATE], seen[TOPIC_ACTION]
    return [(state[k] / 1e9, (action[k] - state[k]) / 1e6, k) for k in state if k in action]


def busy_intervals(history: Path) -> list[tuple[float, float]]:
    """Epoch intervals in which the trainer ran a round (train + gate before each gate line)."""
    import datetime

    from zeus_ros.system.continual_settings import read_history

    out = []
    for event in read_history(history):
        if event.get('event') == 'gate':
            end = datetime.datetime.fromisoformat(event['time']).timestamp()
            out.append((end - event['train_s'] - event['gate_s'], end))
    return out


def first_decision_s(events: list[dict[str, Any]], lat: list[tuple[float, float, int]]
                     ) -> float | None:
    """Seconds from the run's first step to the trainer's first gate decision (None: none)."""
    import datetime

    gates = [datetime.datetime.fromisoformat(e['time']).timestamp() for e in events
             if e.get('event') == 'gate']
    if not gates or not lat:
        return None
    return round(min(gates) - min(t for t, _, _ in lat), 1)


def references(args: argparse.Namespace, deployed: list[Path]) -> list[dict[str, Any]]:
    """In-process returns per episode at the scenario's values and the train values.

    The zoo checkpoint, its oracle and no_context, and every checkpoint the continual run
    deployed, on REFERENCE_SEED (paired across checkpoints; no gate used these seeds).
    """
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.evaluation.evaluate import evaluate_contexts, split_values

    task, zoo_folder, values = SCENARIOS[args.scenario]
    name = _context_name(task)
    scenario = [{name: v} for v in values]
    train = split_values(task, 'train')
    zoo = REPO / 'checkpoints' / zoo_folder
    rows = []
    for label, path in [('zoo zeus (fixed)', zoo / 'zeus.pt'), ('zoo oracle', zoo / 'oracle.pt'),
                        ('zoo no_context', zoo / 'no_context.pt'),
                        *((f'deployed {p.stem}', p) for p in deployed)]:
        agent = InferenceAgent.from_checkpoint(path)
        row: dict[str, Any] = {'checkpoint': label, 'path': str(path)}
        for split, contexts in (('scenario', scenario), ('train', train)):
            returns = np.array([r['return'] for r in evaluate_contexts(
                agent, contexts, episodes=REFERENCE_EPISODES, seed=REFERENCE_SEED,
                progress=False)]).reshape(len(contexts), -1)
            row[f'{split}_return'] = float(returns.mean())
            row[f'{split}_se'] = float(returns.mean(0).std(ddof=1) / np.sqrt(returns.shape[1]))
            row[f'{split}_per_value'] = [round(float(v), 2) for v in returns.mean(1)]
        rows.append(row)
        print(f"{label}: scenario {row['scenario_return']:.1f} ± {row['scenario_se']:.1f}, "
              f"train {row['train_return']:.1f}", flush=True)
    fixed = rows[0]
    best = max(rows[1:3], key=lambda r: r['scenario_return'])
    headroom = best['scenario_return'] - fixed['scenario_return']
    for row in rows:
        row['gap_closed'] = ((row['scenario_return'] - fixed['scenario_return']) / headroom
                             if headroom > 0 else float('nan'))
        worst = min((b - a, b, a) for a, b in zip(fixed['train_per_value'],
                                                   row['train_per_value'], strict=True))
        row['worst_train_change'] = round(worst[0], 2)
        row['worst_train_allowed'] = round(max(2.0, 0.1 * abs(worst[2])), 2)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), default='bias')
    parser.add_argument('--wall', type=float, default=300.0, help='seconds per mode')
    parser.add_argument('--rate', type=float, default=50.0, help='control steps per second')
    parser.add_argument('--every', type=int, default=200, help='steps per context value')
    parser.add_argument('--parallel', action='store_true', help='run the modes side by side')
    parser.add_argument('--burners', type=int, default=0,
                        help='busy processes beside the run (a loaded machine)')
    parser.add_argument('--domain-range', default='150-232',
                        help='ROS domain ids to draw from (FIRST-LAST; tests use 1-100)')
    parser.add_argument('--noise', type=float, default=None,
                        help="the policy's noise (default: what the launch gives each mode)")
    parser.add_argument('--split-s', type=float, default=None)
    parser.add_argument('--new-steps', type=int, default=None)
    parser.add_argument('--warmup', type=int, default=None)
    parser.add_argument('--updates', type=int, default=None)
    parser.add_argument('--bc-weight', type=float, default=None)
    parser.add_argument('--tolerance', type=float, default=None,
                        help="the gate's allowed loss at a train value (default: the trainer's)")
    parser.add_argument('--modes', default='fixed,continual')
    parser.add_argument('--reuse', action='store_true',
                        help='analyse the runs already in --out (info.json) instead of rerunning')
    parser.add_argument('--no-references', action='store_true')
    parser.add_argument('--out', type=Path, default=REPO / 'benchmarks' / 'results' / 'continual')
    args = parser.parse_args()
    args.out = args.out.resolve()  # the launches run in their own folders
    args.out.mkdir(parents=True, exist_ok=True)
    modes = args.modes.split(',')
    task = SCENARIOS[args.scenario][0]
    if args.reuse:
        infos = {m: json.loads((args.out / m / 'info.json').read_text()) for m in modes}
    else:
        infos = run_modes(modes, args)
    summary, rows, deployed = [], [], []
    from zeus_ros.offline.evaluation.continual_report import marks, segments
    from zeus_ros.system.continual_settings import read_history

    for mode in modes:
        folder, info = args.out / mode, infos[mode]
        splits = own_splits(folder, task)  # read once: both figures come from the same splits
        segs = segments(splits, args.rate)
        lat = latencies(splits)
        history = folder / 'rec_continual' / 'history.jsonl'
        busy = busy_intervals(history)
        inside = [ms for t, ms, _ in lat if any(a <= t <= b for a, b in busy)]
        outside = [ms for t, ms, _ in lat if not any(a <= t <= b for a, b in busy)]
        events = read_history(history)
        deployed += [Path(e['checkpoint']) for e in events if e['event'] == 'swap']
        third = [s['return'] for s in segs if s['t_s'] >= 2 * info['wall_s'] / 3 - 10]
        info.update({
            'segments': len(segs), 'swaps': sum(e['event'] == 'swap' for e in events),
            'refusals': sum(e.get('decision') == 'refuse' for e in events),
            'rollbacks': sum(e.get('decision') == 'rollback' for e in events),
            'first_decision_s': first_decision_s(events, lat),
            'last_third_return': float(np.mean(third)) if third else float('nan'),
            'last_third_se': float(np.std(third, ddof=1) / np.sqrt(len(third)))
            if len(third) > 1 else float('nan'),
            'p50_idle_ms': float(np.percentile(outside, 50)) if outside else float('nan'),
            'p99_idle_ms': float(np.percentile(outside, 99)) if outside else float('nan'),
            'p99_busy_ms': float(np.percentile(inside, 99)) if inside else float('nan'),
            'swap_s': marks(events, 'swap', lat, args.rate),
            'rollback_s': marks(events, 'rollback', lat, args.rate),
            'refusal_s': marks(events, 'refuse', lat, args.rate)})
        summary.append(info)
        rows += [{'mode': mode, **s} for s in segs]
        print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in info.items()},
              flush=True)
    by_mode = {i['mode']: i for i in summary}
    if 'fixed' in by_mode and 'continual' in by_mode:
        a, b = by_mode['continual'], by_mode['fixed']
        diff = a['last_third_return'] - b['last_third_return']
        se = float(np.hypot(a['last_third_se'], b['last_third_se']))
        print(f'last third: continual - fixed = {diff:+.1f} ± {se:.1f} per segment '
              f'({diff / se:.1f} s.e.)', flush=True)
    with (args.out / 'segments.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=['mode', 'segment', 't_s', 'context', 'return'])
        writer.writeheader()
        writer.writerows(rows)
    with (args.out / 'summary.csv').open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    _plot(args.out, rows, summary, args.scenario)
    if not args.no_references:
        refs = references(args, deployed)
        with (args.out / 'references.csv').open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(refs[0]))
            writer.writeheader()
            writer.writerows(refs)
    return 0


def _plot(out: Path, rows: list[dict[str, Any]], summary: list[dict[str, Any]],
          scenario: str) -> None:
    from zeus_ros.offline.evaluation.continual_report import plot_modes

    task, _, values = SCENARIOS[scenario]
    plot_modes(out / 'returns.png', rows, summary,
               f'{task}, {_context_name(task)} {min(values)}-{max(values)} (beyond every '
               'preset): fixed vs --continual', 'return per segment (per 40 steps)')


if __name__ == '__main__':
    raise SystemExit(main())
