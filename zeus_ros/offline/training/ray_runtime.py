"""Start or join Ray for `zeus sweep` and `zeus collect --workers`: loopback-only when local.

A plain `ray.init()` binds Ray's servers to the machine's interface address and talks over it
(even with `_node_ip_address='127.0.0.1'`, which Ray maps back to that address). With
RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 in the environment of the driver and of every process Ray
starts, every server listens on 127.0.0.1 and all connections stay on loopback, which is this
project's network rule. A cluster (`--address` or RAY_ADDRESS) is joined as it is: its network
is the cluster operator's choice.
"""

from __future__ import annotations

import os
import sys

__all__ = ['LOOPBACK_ENV', 'cluster_address', 'start_ray']

LOOPBACK_ENV = {
    'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0',  # every Ray server on 127.0.0.1
    'RAY_USAGE_STATS_ENABLED': '0',  # no usage report leaves the machine
}
"""Environment of a local Ray instance (set before Ray starts its processes)."""


def cluster_address(address: str | None) -> str | None:
    """The cluster to join: --address, else RAY_ADDRESS, else None (start a local instance)."""
    return address or os.environ.get('RAY_ADDRESS') or None


def start_ray(address: str | None = None, num_cpus: int | None = None) -> bool:
    """Join `address` (or RAY_ADDRESS), else start a local loopback-only instance.

    Returns True when this call started Ray (the caller then shuts it down), False when Ray
    was already initialised in this process (a test's session, a notebook's).
    """
    target = cluster_address(address)
    if target is None:
        os.environ.update(LOOPBACK_ENV)
    import ray

    if ray.is_initialized():
        return False
    if target is not None:
        ray.init(address=target, log_to_driver=False)
        return True
    from ray._private import ray_constants

    # Read once when ray is imported: a process that imported ray before the line above would
    # still look for its interface address.
    ray_constants.ENABLE_RAY_CLUSTER = False
    ray.init(num_cpus=num_cpus or os.cpu_count() or 1, include_dashboard=False,
             log_to_driver=False, object_store_memory=256 * 2**20,
             _node_ip_address='127.0.0.1', configure_logging=True,
             logging_level='WARNING')
    print(f'ray: local instance on 127.0.0.1 with {int(ray.cluster_resources().get("CPU", 0))} '
          'CPU(s), no dashboard, no usage stats', file=sys.stderr)
    return True
