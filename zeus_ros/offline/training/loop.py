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

from collections.abc import Sequence
from pathlib import Path
import re
import shutil
from typing import Any

from zeus_ros.offline.rollout import (
    next_bag_path,
)
from zeus_ros.offline.training.collect_workers import CollectJob, collect_bag
from zeus_ros.offline.training.train import (
    CHECKPOINT,
    FINAL,
    train,
)

__all__ = ['run_loop']


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
             progress: bool = True, evaluate: bool = True, resume: bool = False,
             readout_steps: int = 0) -> list[Any]:
    """Run the rounds; returns the TrainResult of each round trained. `updates` are per round.

    `readout_steps`: the last round's final.pt carries the read-out (train's `readout_steps`).
    """
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
                             progress=progress,
                             readout_steps=readout_steps if index == rounds - 1 else 0))
    print(f'\nloop: done: {rounds} round(s); deploy {run / FINAL} (zeus launch --checkpoint '
          f'{run / FINAL}; a smaller file with a card: zeus export --checkpoint {run / FINAL} '
          '--out my_policy.pt)')
    return results
