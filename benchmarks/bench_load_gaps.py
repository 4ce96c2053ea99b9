"""Step gaps under CPU load: where a gap over the soak's 1 s comes from (issue 38, item 6).

The three-node loop runs under `zeus launch` as in `make soak` (realtime, the task's 25 Hz, the
shipped checkpoint) beside --burners busy-loop processes, for --seconds. A probe takes every
/zeus/step; a sampler reads, every 50 ms, each node's scheduler accounting
(/proc/PID/task/TID/schedstat: time run and time waited runnable on a run queue) and the nodes
count their garbage collections (benchmarks/gc_probe). For each gap over --report-gap it
prints what filled it:

- `published`: the gap between the two steps' DDS source timestamps (when sim_bridge wrote
  them): the loop's own pace, whatever the observer suffers;
- `transport` / `callback`: the longest delay from write to DDS receipt, and from receipt to
  the probe's callback, of the steps after the gap;
- `waited`: how long each process's executor thread sat runnable but unscheduled (scheduling);
- `burst`: how many steps arrived within 50 ms after the gap (published on time, delivered
  late: the probe or the transport) against one (sim_bridge itself was late);
- `gc`: the longest collection pause per node over the run.

    source scripts/env.sh && python benchmarks/bench_load_gaps.py --seconds 90 --burners 2
    python benchmarks/bench_load_gaps.py --seconds 90 --burners 2 --nice 10   # burners niced
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import threading
import time

from soak import node_pids, params_file

REPO = Path(__file__).resolve().parents[1]
PROBE_DIR = Path(__file__).resolve().parent / 'gc_probe'


def thread_waits(pid: int) -> tuple[int, int]:
    """(run queue wait of the main thread, of all threads) in ns, from schedstat."""
    main = total = 0
    try:
        for task in Path(f'/proc/{pid}/task').iterdir():
            wait = int((task / 'schedstat').read_text().split()[1])
            total += wait
            if task.name == str(pid):
                main = wait
    except (OSError, ValueError, IndexError):
        pass
    return main, total


def sample(pids: dict[str, int], samples: list[tuple[float, dict[str, tuple[int, int]]]],
           stop: threading.Event) -> None:
    """Every 50 ms: each process's run queue waits (main thread, all threads)."""
    while not stop.is_set():
        samples.append((time.monotonic(), {n: thread_waits(p) for n, p in pids.items()}))
        time.sleep(0.05)


def waited(samples: list[tuple[float, dict[str, tuple[int, int]]]], start: float,
           end: float) -> dict[str, float]:
    """Seconds each process's main thread waited runnable between `start` and `end`."""
    inside = [s for s in samples if start - 0.05 <= s[0] <= end + 0.05]
    if len(inside) < 2:
        return {}
    first, last = inside[0][1], inside[-1][1]
    return {n: (last[n][0] - first[n][0]) / 1e9 for n in last if n in first}


def gc_pauses(folder: Path) -> dict[str, str]:
    """Longest collection per node process, from the gc probe's files."""
    found = {}
    for path in sorted(folder.glob('*.txt')):
        lines = path.read_text().splitlines()
        longest = [line.rsplit('longest ', 1)[1] for line in lines if line.startswith('after')
                   and 'longest' in line]
        found[path.stem] = max(longest, key=lambda t: float(t.split()[0])) if longest else '-'
    return found


def main() -> int:
    """Run the loop under load; print gaps and what filled them."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--burners', type=int, default=2)
    parser.add_argument('--nice', type=int, default=0, help='niceness of the burners')
    parser.add_argument('--warmup', type=float, default=20.0)
    parser.add_argument('--report-gap', type=float, default=0.3, help='seconds')
    parser.add_argument('--launch-args', default='', help='extra `zeus launch` arguments')
    parser.add_argument('--max-gap', type=float, default=1.0, help='exit 1 when two steps were '
                        'published further apart (source timestamps; the soak criterion)')
    args = parser.parse_args()
    domain = int(os.environ.get('ROS_DOMAIN_ID') or 150 + os.getpid() % 50)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos
    from zeus_ros.system.processes import ros_env

    with tempfile.TemporaryDirectory() as tmp:
        env = ros_env(domain)
        env.update(ZEUS_GC_PROBE_DIR=str(Path(tmp) / 'gc'), ZEUS_GC_PROBE_WARMUP='15',
                   PYTHONPATH=f'{PROBE_DIR}:{env.get("PYTHONPATH", "")}')
        launch = subprocess.Popen(
            [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params',
             str(params_file(Path(tmp))), '--no-progress', *args.launch_args.split()],
            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
            start_new_session=True)
        rclpy.init(domain_id=domain)
        probe = rclpy.create_node('load_probe')
        arrivals: list[tuple[float, int, int, int, int]] = []

        def on_step(msg: StepFeedback, info: dict[str, int]) -> None:
            """Arrival (monotonic), step, DDS source and receipt times, callback time (ns)."""
            arrivals.append((time.monotonic(), msg.step, info['source_timestamp'],
                             info['received_timestamp'], time.time_ns()))

        probe.create_subscription(StepFeedback, TOPICS.STEP, on_step, step_qos())
        executor = SingleThreadedExecutor()
        executor.add_node(probe)
        burners: list[subprocess.Popen[bytes]] = []
        samples: list[tuple[float, dict[str, tuple[int, int]]]] = []
        stop = threading.Event()
        try:
            while not arrivals or time.monotonic() - arrivals[0][0] < args.warmup:
                executor.spin_once(timeout_sec=0.1)
                if launch.poll() is not None:
                    raise SystemExit(f'zeus launch exited with {launch.returncode}')
            pids = node_pids(launch.pid) | {'probe': os.getpid()}
            burners = [subprocess.Popen(['nice', '-n', str(args.nice), sys.executable, '-c',
                                         'while True: pass']) for _ in range(args.burners)]
            threading.Thread(target=sample, args=(pids, samples, stop), daemon=True).start()
            begin = len(arrivals)
            end = time.monotonic() + args.seconds
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.1)
            stop.set()
        finally:
            for burner in burners:
                burner.kill()
            launch.terminate()
            launch.wait(timeout=30)
            probe.destroy_node()
            rclpy.try_shutdown()
        pauses = gc_pauses(Path(tmp) / 'gc')
    run = arrivals[begin:]
    gaps = [(run[i][0] - run[i - 1][0], i) for i in range(1, len(run))]
    long = [(g, i) for g, i in gaps if g > args.report_gap]
    published = [(run[i][2] - run[i - 1][2]) / 1e9 for i in range(1, len(run))]
    transport = [(r[3] - r[2]) / 1e9 for r in run]
    callback = [(r[4] - r[3]) / 1e9 for r in run]
    seconds = run[-1][0] - run[0][0] if len(run) > 1 else 0.0
    load = os.getloadavg()[0]
    print(f'load gaps: {len(run)} steps in {seconds:.1f} s ({len(run) / max(seconds, 1e-9):.1f}/s)'
          f' with {args.burners} burner(s) at nice {args.nice}, load average {load:.1f}; '
          f'gaps over {args.report_gap} s: {len(long)}, over 1 s: '
          f'{sum(g > 1.0 for g, _ in gaps)}, longest {max(gaps)[0] * 1000:.0f} ms')
    print(f'  published (source timestamps): longest gap {max(published) * 1000:.0f} ms, over '
          f'1 s: {sum(g > 1.0 for g in published)}; longest transport delay '
          f'{max(transport) * 1000:.0f} ms; longest receipt-to-callback {max(callback) * 1000:.0f}'
          ' ms')
    for gap, i in sorted(long, reverse=True)[:10]:
        t0, t1 = run[i - 1][0], run[i][0]
        burst = sum(1 for t, *_ in run[i:] if t - t1 <= 0.05)
        jump = run[i][1] - run[i - 1][1]
        waits = ', '.join(f'{n} {w * 1000:.0f}' for n, w in waited(samples, t0, t1).items())
        after = run[i:i + max(burst, 1)]
        print(f'  gap {gap * 1000:.0f} ms before step {run[i][1]} (+{jump} steps): published '
              f'{published[i - 1] * 1000:.0f} ms apart; transport '
              f'{max((r[3] - r[2]) / 1e6 for r in after):.0f} ms, callback '
              f'{max((r[4] - r[3]) / 1e6 for r in after):.0f} ms; burst {burst}; main threads '
              f'waited runnable (ms): {waits}')
    print('  longest gc pause after warm-up: ' + ', '.join(f'{n} {p}' for n, p in pauses.items()))
    if not published or max(published) > args.max_gap:
        print(f'load gaps: FAILED: the loop published two steps more than {args.max_gap} s apart'
              if published else 'load gaps: FAILED: no step', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
