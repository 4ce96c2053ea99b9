"""Several distillation seeds in one process: torch.func.vmap against one seed after another.

Why (issue 36): training seeds as a batched ensemble is a gain where one seed leaves the
hardware idle (small kernels on a GPU). A `zeus distill` update is the conv phi's forward and
backward on 120 frame stacks (the rest of the update is a few percent); this measures exactly
that for S students: S encoders one after another, against the same S encoders stacked
(`torch.func.stack_module_state`) and run as one `vmap`ped call, interleaved repeats, median.
It prints milliseconds per round of S updates, the ratio, and seeds x updates per hour.

    source scripts/env.sh && python benchmarks/bench_distill_seeds.py [--seeds 3] [--repeats 5]
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path
import statistics
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> None:
    import torch
    from torch.func import functional_call, stack_module_state, vmap

    from zeus_ros.learning.config import load_config
    from zeus_ros.learning.inference import InferenceAgent
    from zeus_ros.offline.training.distill import DEFAULT_CONFIG, make_student

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=3)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--threads', type=int, default=1, help='torch threads (zeus distill: 1)')
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    teacher = InferenceAgent.from_checkpoint(REPO / 'checkpoints' / 'cheetah_bias_v0' / 'zeus.pt')
    config = load_config(DEFAULT_CONFIG)
    encoders = [make_student(config.replace(seed=seed), teacher, teacher.task).modules['encoder']
                for seed in range(args.seeds)]
    windows, window = config.batch_size // 20, 20
    stacks = (windows * (window + teacher.k), 9, 84, 84)  # what one update encodes
    frames = torch.randint(0, 255, (args.seeds, *stacks), dtype=torch.uint8)

    def one_after_another() -> None:
        for encoder, batch in zip(encoders, frames, strict=True):
            encoder(batch).square().mean().backward()

    params, buffers = stack_module_state(encoders)
    skeleton = copy.deepcopy(encoders[0]).to('meta')

    def batched() -> None:
        out = vmap(lambda p, b, x: functional_call(skeleton, (p, b), (x,)))(
            params, buffers, frames)
        out.square().mean().backward()

    times: dict[str, list[float]] = {'one after another': [], 'vmap': []}
    for run in (one_after_another, batched):
        run()  # warm-up
    for _ in range(args.repeats):
        for name, run in (('one after another', one_after_another), ('vmap', batched)):
            started = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - started)
    print(f'{args.seeds} students, {stacks[0]} frame stacks each per update, '
          f'{args.threads} torch thread(s), median of {args.repeats}:')
    median = {name: statistics.median(values) for name, values in times.items()}
    for name, seconds in median.items():
        print(f'  {name:18s} {seconds * 1e3:7.1f} ms per {args.seeds} updates   '
              f'{args.seeds * 3600 / seconds:8.0f} seeds x updates per hour')
    print(f'  vmap / one after another: {median["one after another"] / median["vmap"]:.2f}x '
          'the throughput')


if __name__ == '__main__':
    main()
