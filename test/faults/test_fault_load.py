"""Fault matrix, load row: the loop keeps its pace beside two CPU burners (make faults only).

benchmarks/bench_load_gaps.py runs the three-node loop under `zeus launch` in realtime mode
(25 Hz) beside two busy loops on this 2-core machine and fails when sim_bridge published two
steps more than 1 s apart (DDS source timestamps: the loop's own pace; how late the probe got
them is reported, not judged). 30 s of load: the long runs are in docs/faults.md.
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from ros_harness import REPO, fresh_domain_id, ros_environment

pytestmark = [pytest.mark.ros, pytest.mark.faults_only]


def test_the_loop_publishes_every_step_within_1_s_beside_two_cpu_burners() -> None:
    done = subprocess.run(
        [sys.executable, 'bench_load_gaps.py', '--seconds', '30', '--warmup', '10',
         '--burners', '2', '--max-gap', '1.0'], cwd=REPO / 'benchmarks',
        env=ros_environment(fresh_domain_id()), capture_output=True, text=True, timeout=300,
        check=False)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-3000:]
    published = re.search(r'published \(source timestamps\): longest gap (\d+) ms', output)
    assert published and int(published.group(1)) < 1000, output[-3000:]
    print(output.strip().splitlines()[0])
    print(output.strip().splitlines()[1])
