"""`zeus loop`: record -> retrain -> redeploy as one command (in-process, no ROS).

Round 0 collects uniform-random steps and trains from scratch; every later round collects with
the newest checkpoint plus exploration noise (the policy as deployed, via rollout.AgentPolicy),
appends that bag and resumes training on all bags. `--resume` continues a stopped or finished
loop up to --rounds: rounds whose bag exists are not collected again, rounds whose updates are
in the checkpoint are not trained again (round i always collects with seed + i, so a loop
extended from 5 to 10 rounds is the 10-round loop). Each round continues the context schedule
where the earlier rounds' bags stopped (their steps and episode starts), rather than starting
it over: one value per episode over 8 values would otherwise, with 500-step episodes and 2,000
steps per round, never collect the last four. A resume after a kill during collection
recovers the unfinished bag (as `zeus recover` does; one without a single complete step is moved
to unfinished/) and collects the steps the round still lacks into bag_NNN_restK before training.
Layout under --out:
  bags/bag_NNN (one bag per round)   run/ (the `zeus train` run directory: checkpoints, metrics)
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
import json
from pathlib import Path
import re
import shutil
import signal
import sys
from typing import Any

from zeus_ros.cli_args import TASK_HELP, ZeusArgumentParser, at_least, input_path, task_name
from zeus_ros.config_sets import SET_HELP, apply_sets, parse_sets, refuse_both, set_items
from zeus_ros.learning.methods import METHODS
from zeus_ros.offline.rollout import (
    DEFAULT_SCHEDULE,
    SCHEDULE_HELP,
    next_bag_path,
    parse_schedule,
)
from zeus_ros.offline.training.collect_workers import CollectJob, collect_bag
from zeus_ros.offline.training.train import (
    CHECKPOINT,
    FINAL,
    TrainError,
    apply_overrides,
    check_device,
    own_flags,
    read_config,
    train,
)

__all__ = ['main', 'run_loop']


_ROUND_BAG = re.compile(r'bag_(\d+)')


def _round_bags(bags: Path, index: int) -> list[Path]:
    """Round `index`'s bag and those that completed it after an interruption (bag_NNN_restK)."""
    return sorted(p for p in bags.glob(f'bag_{index:03d}*') if p.is_dir()
                  and re.fullmatch(rf'bag_{index:03d}(_rest\d+)?', p.name))


def _bag_steps(bag: Path) -> int:
    """Control steps in a closed bag: the /zeus/step messages its metadata counts."""
    from rosbags.rosbag2 import Reader

    from zeus_ros.bags.schema import TOPIC_STEP

    reader = Reader(bag)
    reader.open()
    try:
        return sum(int(c.msgcount) for c in reader.connections if c.topic == TOPIC_STEP)
    finally:
        reader.close()


def _schedule_position(bags: Sequence[Path]) -> tuple[int, int]:
    """(steps, episode starts) the collections in `bags` took of the context schedule.

    A round continues the schedule from here (CollectJob.schedule_start): counted from the
    bags themselves, so a resumed or extended loop continues it exactly as an unbroken one.
    """
    from rosbags.rosbag2 import Reader

    from zeus_ros.bags.schema import MSGTYPES, TOPIC_STEP, codec

    steps = episodes = 0
    decode = codec().deserialize
    for bag in bags:
        key = (bag.resolve(), (bag / 'metadata.yaml').stat().st_mtime_ns)
        if key not in _POSITIONS:  # a closed bag does not change: read each once per process
            counted = [0, 0]
            reader = Reader(bag)
            reader.open()
            try:
                connections = [c for c in reader.connections if c.topic == TOPIC_STEP]
                for _connection, _time, raw in reader.messages(connections=connections):
                    counted[0] += 1
                    counted[1] += bool(decode(raw, MSGTYPES[TOPIC_STEP]).first)
            finally:
                reader.close()
            _POSITIONS[key] = (counted[0], counted[1])
        steps += _POSITIONS[key][0]
        episodes += _POSITIONS[key][1]
    return steps, episodes


_POSITIONS: dict[tuple[Path, int], tuple[int, int]] = {}


def _recover_unfinished(out: Path, bags: Path) -> None:
    """Recover bags a kill left without metadata or footer; move aside those with no step.

    Without this, training would stop on the unfinished bag (or, after a manual recover,
    silently train on a cut round).
    """
    from zeus_ros.bags.errors import BagError
    from zeus_ros.bags.recover import needs_recovery, recover_bag

    for bag in sorted(p for p in bags.glob('bag_*') if p.is_dir()):
        if not needs_recovery(bag):
            continue
        print(f'loop: {bag} is unfinished (not closed: the collection was killed); '
              'recovering it as `zeus recover` does')
        try:
            report = recover_bag(bag)
            steps = _bag_steps(bag)
        except (BagError, OSError, ValueError) as error:
            report, steps = None, 0
            print(f'loop: {bag} cannot be recovered ({error})')
        except Exception as error:  # rosbags' ReaderError on a bag with no complete message
            report, steps = None, 0
            print(f'loop: {bag} cannot be read after recovery ({error})')
        if steps == 0:
            aside = out / 'unfinished' / bag.name
            aside.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(bag, aside)
            print(f'loop: {bag} held no complete step; moved it to {aside}')
        elif report is not None:
            print(f'loop: {report.summary()}')


def _collect_round(task_name: str, schedule: dict[str, Any], bags: Path, steps: int, *,
                   seed: int, checkpoint: Path | None, noise: float, pixels: bool,
                   progress: bool, stochastic: bool = False, bag: Path | None = None,
                   after: Sequence[Path] = ()) -> Path:
    """One collection: random without a checkpoint, else the agent (sampled, or mode + noise).

    It continues the context schedule where the collections of the bags `after` stopped.
    """
    bag = bag or next_bag_path(bags, append=True)
    start = _schedule_position(after)
    stats = collect_bag(CollectJob(task_name, schedule, bag, steps, seed, checkpoint=checkpoint,
                                   noise=noise, stochastic=stochastic, pixels=pixels,
                                   progress=progress, schedule_start=start))
    print(f'loop: wrote {stats.steps} steps ({stats.episodes} episode starts) to {bag} '
          f'in {stats.seconds:.1f} s (schedule from step {start[0]}, episode {start[1]})')
    return bag


def run_loop(task: str, config: Any, out: str | Path, *, rounds: int, random_steps: int,
             steps: int, updates: int, noise: float, schedule: dict[str, Any], seed: int,
             progress: bool = True, evaluate: bool = True, resume: bool = False) -> list[Any]:
    """Run the rounds; returns the TrainResult of each round trained. `updates` are per round."""
    from zeus_ros.offline.training.train import checkpoint_step

    out = Path(out)
    bags, run = out / 'bags', out / 'run'
    pixels = config.obs_kind == 'pixels'
    if resume and bags.is_dir():
        _recover_unfinished(out, bags)
    done_bags = len([p for p in bags.glob('bag_*') if p.is_dir()
                     and _ROUND_BAG.fullmatch(p.name)]) if resume else 0
    done_updates = checkpoint_step(run / CHECKPOINT) if resume else 0
    done_final = checkpoint_step(run / FINAL) if resume else 0
    if resume:
        print(f'loop: resuming {out}: {done_bags} bag(s), checkpoint at update {done_updates}')
    results = []
    for index in range(rounds):
        total = updates * (index + 1)
        if index < done_bags and (done_updates > total or done_final >= total):
            continue
        if index < done_bags and done_updates == total:  # killed between its last two writes
            print(f'loop: round {index + 1}/{rounds} trained to update {total}, but '
                  f'{run / FINAL} is ' + (f'from update {done_final}' if done_final else
                                          'missing') + ': writing it from its checkpoint')
        checkpoint = None if index == 0 else run / CHECKPOINT
        stochastic = config.exploration == 'stochastic'
        how = 'sampled (stochastic SAC policy)' if stochastic else f'+ noise {noise}'
        what = 'random policy' if checkpoint is None else f'{checkpoint} {how}'
        count = random_steps if index == 0 else steps
        if index >= done_bags:
            print(f'\nloop: round {index + 1}/{rounds}: collect {count} steps with {what}')
            _collect_round(task, schedule, bags, count, seed=seed + index,
                           checkpoint=checkpoint, noise=noise, pixels=pixels,
                           progress=progress, stochastic=stochastic,
                           after=[b for i in range(index) for b in _round_bags(bags, i)])
        else:
            held = _round_bags(bags, index)
            have = sum(_bag_steps(b) for b in held)
            if have < count:
                part = len(held)
                print(f'\nloop: round {index + 1}/{rounds}: {", ".join(b.name for b in held)} '
                      f'hold(s) {have} of the {count} steps requested (the collection was '
                      f'interrupted); collecting the missing {count - have} with {what}')
                _collect_round(task, schedule, bags, count - have,
                               seed=seed + index + 7919 * part, checkpoint=checkpoint,
                               noise=noise, pixels=pixels, progress=progress,
                               stochastic=stochastic,
                               bag=bags / f'bag_{index:03d}_rest{part}',
                               after=[b for i in range(index + 1) for b in _round_bags(bags, i)])
        print(f'loop: round {index + 1}/{rounds}: train on {bags} up to update {total}')
        results.append(train([bags], config.replace(num_updates=total), run, task=task,
                             resume=index > 0 or done_updates > 0
                             or (run / CHECKPOINT).exists(), evaluate=evaluate,
                             progress=progress))
    print(f'\nloop: done: {rounds} round(s); deploy {run / FINAL} (export it: zeus export '
          f'--checkpoint {run / FINAL} --out my_policy.pt)')
    return results


LOOP_JSON = 'loop.json'
"""The loop's flags, stored in --out at the start, so `--resume` needs only --out and --rounds."""
DEFAULTS: dict[str, Any] = {'random_steps': 1500, 'steps': 1500, 'updates': None,
                            'noise': 0.2, 'schedule': DEFAULT_SCHEDULE, 'method': None,
                            'seed': None, 'device': None, 'no_eval': False, 'set': []}
STORED = ('task', 'config', *DEFAULTS)


def _build_parser() -> argparse.ArgumentParser:
    parser = ZeusArgumentParser(
        prog='zeus loop', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Random collection -> train -> collect with the new policy -> retrain '
        '(resume), appending bags, for N rounds. The flags are stored in OUT/loop.json; '
        '--resume reads them, so `zeus loop --out OUT --rounds 6 --resume` continues a loop '
        '(a flag given again overrides the stored one).', epilog=SCHEDULE_HELP)
    parser.add_argument('--task', type=task_name, help=f'{TASK_HELP} (required unless --resume)')
    parser.add_argument('--config', type=Path,
                        help='training config YAML, e.g. params/train/state_cpu.yaml (found in '
                        'the package share too; required unless --resume)')
    parser.add_argument('--out', type=Path, required=True, help='folder for bags/ and run/')
    parser.add_argument('--rounds', type=at_least(1), default=2, help='collect+train rounds')
    parser.add_argument('--random-steps', type=at_least(0),
                        help="uniform-random steps of round 1 (default 1500, the paper's seed "
                        'steps)')
    parser.add_argument('--steps', type=at_least(0),
                        help='steps collected with the policy in each later round (default 1500)')
    parser.add_argument('--updates', type=at_least(0),
                        help='updates per round (default: the config num_updates)')
    parser.add_argument('--noise', type=at_least(0.0, float),
                        help='exploration noise, fraction of half the action range (default 0.2; '
                        "with the config's exploration: noise; exploration: stochastic samples "
                        'the SAC policy instead)')
    parser.add_argument('--schedule',
                        help='context schedule while collecting (default: '
                        f'{DEFAULTS["schedule"]}, one train value per episode in turn: the '
                        'critic can value a context that holds for the episode, and the '
                        'policy learns to adapt (docs/results.md, session 7); grammar below)')
    parser.add_argument('--set', nargs='+', action='extend', metavar='KEY=VALUE',
                        help=f'{SET_HELP}; on --resume added to the stored ones')
    parser.add_argument('--method', choices=METHODS, help='override the config method')
    parser.add_argument('--seed', type=at_least(0), help='override the config seed')
    parser.add_argument('--device', help='override the config device: auto, cpu, cuda[:N]')
    parser.add_argument('--resume', action='store_true',
                        help='continue the loop in --out up to --rounds with its stored flags')
    parser.add_argument('--no-eval', action='store_true', default=None,
                        help='skip periodic evaluation')
    parser.add_argument('--no-progress', action='store_true', help='hide progress bars')
    return parser


def settle_flags(args: argparse.Namespace) -> argparse.Namespace:
    """Fill the loop's flags: given > stored in OUT/loop.json (on --resume) > defaults.

    Raises ValueError for a fresh loop without --task/--config or a resume with another task.
    """
    stored: dict[str, Any] = {}
    path = args.out / LOOP_JSON
    if args.resume and path.is_file():
        try:
            stored = json.loads(path.read_text())
        except (OSError, ValueError) as error:
            raise ValueError(f'{path}: cannot read the stored flags ({error}); repeat the '
                             'flags of the first run') from None
    if args.task is not None and stored.get('task') not in (None, args.task):
        raise ValueError(f'--task {args.task}: the loop in {args.out} runs {stored["task"]}')
    if args.set is not None:  # given --set items override the stored ones field by field
        args.set = set_items({**parse_sets(stored.get('set') or [], f'{path}: set'),
                              **parse_sets(args.set)})
    for key in STORED:
        if getattr(args, key) is None:
            setattr(args, key, stored.get(key, DEFAULTS.get(key)))
    missing = [f'--{key}' for key in ('task', 'config') if getattr(args, key) is None]
    if missing:
        where = f' ({path} is missing)' if args.resume else ''
        raise ValueError(f'{" and ".join(missing)} required{where}')
    args.config = input_path(args.config, '--config').resolve()
    return args


def _store_flags(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    flags = {key: str(value) if isinstance(value, Path) else value
             for key, value in vars(args).items() if key in STORED}
    (args.out / LOOP_JSON).write_text(json.dumps(flags, indent=1) + '\n')


def main(argv: list[str] | None = None) -> int:
    """Entry point of `zeus loop`; returns the process exit code."""
    from zeus_ros.bags.errors import BagError, IngestError
    from zeus_ros.learning.errors import CheckpointError, ConfigError

    args = _build_parser().parse_args(argv)
    try:
        args = settle_flags(args)
    except ValueError as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    for flag in ('rounds', 'random_steps', 'steps'):
        if getattr(args, flag) < 1:
            print(f'zeus loop: --{flag.replace("_", "-")} must be >= 1', file=sys.stderr)
            return 2
    started = (args.out / 'run' / CHECKPOINT).exists() or any((args.out / 'bags').glob('bag_*'))
    if started and not args.resume:
        print(f'zeus loop: {args.out} already holds a loop run (bags or a checkpoint); pass '
              '--resume to continue it (an unfinished bag is recovered and completed) or '
              'choose another --out', file=sys.stderr)
        return 2
    try:
        sets = parse_sets(args.set)
        refuse_both(sets, own_flags(args))
        config = apply_overrides(apply_sets(read_config(args.config), sets), method=args.method,
                                 seed=args.seed, device=args.device)
        check_device(config.device, '--device' if args.device else
                     f'--config {args.config}: device')
        schedule = parse_schedule(args.schedule)
    except (ConfigError, ValueError) as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    _store_flags(args)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        run_loop(args.task, config, args.out, rounds=args.rounds,
                 random_steps=args.random_steps, steps=args.steps,
                 updates=args.updates or config.num_updates, noise=args.noise,
                 schedule=schedule, seed=config.seed, progress=not args.no_progress,
                 evaluate=not args.no_eval, resume=args.resume)
    except (TrainError, ConfigError, CheckpointError, BagError, IngestError,
            ValueError) as error:
        print(f'zeus loop: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('zeus loop: interrupted; bags and the latest checkpoint are kept in '
              f'{args.out}', file=sys.stderr)
        return 130
    except Exception as error:  # a full disk is one line (torch wraps ENOSPC); else a bug
        from zeus_ros.atomic_file import disk_full_message
        from zeus_ros.offline.rollout import CollectDiskFull

        full = str(error) if isinstance(error, CollectDiskFull) else \
            disk_full_message(error, args.out)
        if full is None:
            raise
        print(f'zeus loop: {full}; `zeus loop --resume` goes on once there is space',
              file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
