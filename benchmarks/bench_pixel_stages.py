"""Where a pixel step's time goes, stage by stage, with a shipped pixel checkpoint (issue 36).

One process runs the family's task and the checkpoint as the live nodes do (InferenceAgent
with each frame encoded once, ContextHistory, FrameStack) and times every stage of every step:

- `render`: MuJoCo draws the 84x84 frame (sim_bridge's cost before it publishes o_k);
- `stack`: the frame joins the 3-frame stack (the nodes' ObservationDecoder does the same);
- `encode`: phi of the new stack, once (`encode_ahead`; psi and the actor reuse it);
- `psi`: psi over the last k transitions' features;
- `act`: the actor's head on [phi(o_k), psi];
- `simulate`: the physics step with the action.

`obs -> action` is stack + encode + psi + act: what the loop adds between a frame and its
action when everything runs in one process (the issue's target: p99 <= 10 ms); the rendered
rate is what one core sustains with rendering included.

    source scripts/env.sh && python benchmarks/bench_pixel_stages.py [--steps 400]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
STAGES = ('render', 'stack', 'encode', 'psi', 'act', 'simulate')


def measure(checkpoint: Path, steps: int, seed: int) -> dict[str, np.ndarray]:
    """Milliseconds per stage per step (the first episode's first step excluded: warm-up)."""
    import torch

    from sim_bridge.env import ScheduledEnv
    from sim_bridge.registry import make_task
    from sim_bridge.schedules import schedule_from_config
    from zeus_ros.learning.frames import FrameStack
    from zeus_ros.learning.inference import InferenceAgent

    torch.set_num_threads(1)  # as the nodes run
    agent = InferenceAgent.from_checkpoint(checkpoint, reuse_features=True)
    if agent.obs_kind != 'pixels':
        raise SystemExit(f'{checkpoint} is a {agent.obs_kind} checkpoint; give a pixel one')
    task = make_task(agent.task, seed=seed)
    env = ScheduledEnv(task, schedule_from_config(
        {'kind': 'switch', 'values': 'train', 'every': 100}, task, seed))
    frames, history = FrameStack(), agent.new_history()
    size = agent.obs_shape[-1]
    times = {stage: [] for stage in STAGES}
    es, previous = env.reset(), None
    for _ in range(steps + 1):
        t0 = time.perf_counter()
        frame = task.render(size, size)
        t1 = time.perf_counter()
        first = es.observation.first
        obs = frames.reset(frame) if first else frames.push(frame)
        t2 = time.perf_counter()
        agent.encode_ahead(obs)
        t3 = time.perf_counter()
        if first or previous is None:
            history.clear()
        else:
            history.push(previous, es.applied_action, es.observation.reward, obs)
        previous = obs
        context = agent.context(history)
        t4 = time.perf_counter()
        action = agent.act(obs, context)
        t5 = time.perf_counter()
        es = env.step(action)
        t6 = time.perf_counter()
        for stage, (a, b) in zip(STAGES, ((t0, t1), (t1, t2), (t2, t3), (t3, t4), (t4, t5),
                                          (t5, t6)), strict=True):
            times[stage].append((b - a) * 1e3)
    task.close()
    return {stage: np.asarray(values[1:]) for stage, values in times.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--checkpoint', type=Path,
                        default=REPO / 'checkpoints' / 'cheetah_bias_v0' / 'pixels_student.pt')
    parser.add_argument('--steps', type=int, default=400)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=Path, default=None, help='also write stages.csv here')
    args = parser.parse_args()
    times = measure(args.checkpoint, args.steps, args.seed)
    times['obs -> action'] = times['stack'] + times['encode'] + times['psi'] + times['act']
    total = sum(times[stage] for stage in STAGES)
    rows = [{'stage': stage, 'p50_ms': float(np.percentile(v, 50)),
             'p99_ms': float(np.percentile(v, 99)), 'mean_ms': float(v.mean())}
            for stage, v in times.items()]
    print(f'{args.checkpoint.name}: {args.steps} steps, one process, 1 torch thread')
    print(f'{"stage":<14} {"p50 ms":>8} {"p99 ms":>8} {"mean ms":>8}')
    for row in rows:
        print(f'{row["stage"]:<14} {row["p50_ms"]:8.2f} {row["p99_ms"]:8.2f} '
              f'{row["mean_ms"]:8.2f}')
    print(f'rendered loop: {1e3 / total.mean():.1f} steps/s; obs -> action p99 '
          f'{np.percentile(times["obs -> action"], 99):.2f} ms (target <= 10 ms in one process)')
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        with (args.out / 'stages.csv').open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
