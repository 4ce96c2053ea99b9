"""Soak: the three-node loop (`zeus launch`, the shipped checkpoint) for a long time.

Fails (exit 1) when a node's resident memory grows by more than --max-rss-growth MiB between
the end of the warm-up and the end of the run, or when sim_bridge published two consecutive
/zeus/step messages more than --max-gap seconds apart (their DDS source timestamps: the loop's
own pace), or when a node exits. How late they reached this probe is reported beside it: under
CPU burners the probe itself waits for a core, and that is not the loop stalling
(benchmarks/bench_load_gaps.py, docs/faults.md). sim_bridge runs in realtime
mode at the task's own rate: a deployment's pace, and the machine stays usable meanwhile.

    source scripts/env.sh && python benchmarks/soak.py --minutes 60      # `make soak`
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import threading
import time

import yaml

from zeus_ros.system.processes import group_domain_id

REPO = Path(__file__).resolve().parents[1]
NODES = {'sim_bridge': 'sim_bridge_node', 'context_estimator': 'context_estimator_node',
         'policy': 'policy_node'}


def rss_mib(pid: int) -> float:
    """Resident memory of one process in MiB, from /proc."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024
    return float('nan')


def node_pids(parent: int) -> dict[str, int]:
    """Pid of each node `zeus launch` (pid `parent`) started."""
    found = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            argv = (entry / 'cmdline').read_bytes().decode(errors='replace')
        except OSError:
            continue
        for name, module in NODES.items():
            if ppid == parent and f'zeus_ros.nodes.{module}' in argv:
                found[name] = int(entry.name)
    return found


def params_file(folder: Path) -> Path:
    """params/zeus.yaml with sim_bridge (and the QoS of its peers) in realtime mode."""
    params = yaml.safe_load((REPO / 'params' / 'zeus.yaml').read_text())
    for name in NODES:
        params[f'/**/{name}']['ros__parameters']['mode'] = 'realtime'
    for name in ('context_estimator', 'policy'):
        section = params[f'/**/{name}']['ros__parameters']
        section['checkpoint'] = str(REPO / section['checkpoint'])
    path = folder / 'soak.yaml'
    path.write_text(yaml.safe_dump(params))
    return path


_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def _unblock_signals() -> None:
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGNALS)


def _watch_signals() -> list[str]:
    """Take SIGINT/SIGTERM in a thread that says who sent them: an interrupted soak names why.

    They are blocked here and in the DDS threads rclpy starts later (launch is already running).
    """
    signals = _SIGNALS
    signal.pthread_sigmask(signal.SIG_BLOCK, signals)
    stop: list[str] = []

    def wait() -> None:
        info = signal.sigwaitinfo(signals)
        try:
            sender = Path(f'/proc/{info.si_pid}/cmdline').read_bytes().replace(b'\0', b' ')
        except OSError:
            sender = b'(gone)'
        stop.append(f'{signal.Signals(info.si_signo).name} from pid {info.si_pid} '
                    f'({sender.decode(errors="replace").strip()[:200]})')

    threading.Thread(target=wait, daemon=True).start()
    return stop


def main() -> int:
    """Run the soak; print the figures; exit 1 on a failed criterion."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--minutes', type=float, default=60.0)
    parser.add_argument('--warmup', type=float, default=60.0, help='seconds before the RSS '
                        'baseline (imports, first inferences, DDS buffers)')
    parser.add_argument('--max-rss-growth', type=float, default=5.0, help='MiB per node')
    parser.add_argument('--max-gap', type=float, default=1.0, help='seconds between steps')
    parser.add_argument('--report-every', type=float, default=300.0,
                        help='seconds between progress lines (figures so far)')
    parser.add_argument('--burners', type=int, default=0, help='busy-loop processes beside '
                        'the loop from the baseline on (the load row of docs/faults.md: 2)')
    args = parser.parse_args()
    burners: list[subprocess.Popen[bytes]] = []
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    stop = _watch_signals()  # before any import starts a thread
    domain = group_domain_id()  # $ROS_DOMAIN_ID, else one from $ZEUS_DOMAIN_RANGE

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from zeus_msgs.msg import StepFeedback

    from zeus_ros.nodes.topics import TOPICS, step_qos

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
        launch = subprocess.Popen(
            [sys.executable, '-m', 'zeus_ros.cli', 'launch', '--params',
             str(params_file(Path(tmp)))], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=_unblock_signals)
        rclpy.init(domain_id=domain)
        probe = rclpy.create_node('soak_probe')
        # count, last arrival, longest arrival gap, last source stamp, longest published gap
        arrivals: list[float] = [0, 0.0, 0.0, 0.0, 0.0]
        started_at: list[float] = []

        def on_step(_msg: StepFeedback, info: dict[str, int]) -> None:
            now, source = time.monotonic(), info['source_timestamp'] / 1e9
            if arrivals[0]:
                arrivals[2] = max(arrivals[2], now - arrivals[1])
                arrivals[4] = max(arrivals[4], source - arrivals[3])
            else:
                started_at.append(now)
            arrivals[0] += 1
            arrivals[1] = now
            arrivals[3] = source

        probe.create_subscription(StepFeedback, TOPICS.STEP, on_step, step_qos())
        executor = SingleThreadedExecutor()
        executor.add_node(probe)
        baseline: dict[str, float] = {}
        failed = ''
        end = None
        report_at = 0.0
        try:
            while True:
                try:
                    executor.spin_once(timeout_sec=0.1)
                except (KeyboardInterrupt, ExternalShutdownException):
                    stop.append('a signal')
                if stop:
                    failed = f'interrupted by {stop[0]} before the end'
                    break
                if launch.poll() is not None:
                    failed = f'zeus launch exited with {launch.returncode}'
                    break
                if not started_at:
                    continue
                now = time.monotonic()
                if not baseline and now - started_at[0] >= args.warmup:
                    pids = node_pids(launch.pid)
                    baseline = {name: rss_mib(pid) for name, pid in pids.items()}
                    arrivals[2] = arrivals[4] = 0.0  # gaps count from the baseline on
                    end = now + args.minutes * 60
                    burners = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                               for _ in range(args.burners)]
                    print(f'soak: baseline RSS (MiB) {baseline}; running {args.minutes} min',
                          flush=True)
                if baseline and now >= report_at:
                    report_at = now + args.report_every
                    sizes = {name: rss_mib(pid) for name, pid in node_pids(launch.pid).items()}
                    print(f'soak: +{(now - started_at[0]) / 60:.0f} min, {int(arrivals[0])} '
                          f'steps, longest gap {arrivals[4] * 1000:.0f} ms (as received '
                          f'{arrivals[2] * 1000:.0f} ms), RSS growth (MiB) '
                          + ', '.join(f'{n} {sizes.get(n, float("nan")) - v:+.2f}'
                                      for n, v in baseline.items()), flush=True)
                if end is not None and now >= end:
                    break
            final = {name: rss_mib(pid) for name, pid in node_pids(launch.pid).items()}
        finally:
            for burner in burners:
                burner.kill()
            if launch.poll() is None:  # SIGTERM: SIGINT is ignored in a background job
                launch.terminate()
                launch.wait(timeout=30)
            probe.destroy_node()
            rclpy.try_shutdown()
    growth = {name: final.get(name, float('nan')) - rss for name, rss in baseline.items()}
    steps, gap = int(arrivals[0]), arrivals[4]
    print(f'soak: {steps} steps; longest step gap {gap * 1000:.0f} ms as published (as received '
          f'here {arrivals[2] * 1000:.0f} ms); RSS growth (MiB) '
          + ', '.join(f'{name} {value:+.2f}' for name, value in growth.items()))
    if not failed and not baseline:
        failed = 'the loop never ran past the warm-up'
    bad = [name for name, value in growth.items() if not value <= args.max_rss_growth]
    if failed:
        pass  # the first reason stands
    elif bad:
        failed = f'RSS grew more than {args.max_rss_growth} MiB: {bad}'
    elif gap > args.max_gap:
        failed = f'a step gap of {gap:.2f} s (limit {args.max_gap} s)'
    if failed:
        print(f'soak: FAILED: {failed}', file=sys.stderr)
        return 1
    print('soak: passed')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
