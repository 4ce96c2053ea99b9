"""`zeus launch`'s restart policy per node: how often, within which window, after which delay.

As ros2_control's controllers fall back to a safe command while one restarts, the loop does not
stop when the context estimator, the policy or the recorder dies: the bridge applies its safe
action (its action timeout) until the restarted node is back and re-paired. A node that dies
more than `limit` times within `window_s` seconds is given up: for a node of the control loop
that stops the group (it is broken, not unlucky), for the recorder the run goes on unrecorded.

Set in the params file, in a section no node reads (the ROS params layout, so the same file
still goes to every node):

    /**/zeus_launch:
      ros__parameters:
        respawn:
          policy: {limit: 3, window_s: 60.0, backoff_s: 1.0}
          sim_bridge: {limit: 0}        # 0: never restarted (the default for the bridges)

or on the command line: `zeus launch --respawn policy=3/60/1 --respawn recorder=0`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
import math
from typing import Any

__all__ = ['DEFAULT_POLICIES', 'LAUNCH_SECTION', 'RespawnPolicy', 'RespawnState',
           'parse_cli', 'policies_from_params']

LAUNCH_SECTION = 'zeus_launch'
"""The params file section `zeus launch` reads its own settings from (no node has this name)."""
MAX_BACKOFF_S = 30.0
"""The delay before a restart doubles per restart in the window, up to this."""


@dataclass(frozen=True)
class RespawnPolicy:
    """Restart a dead node up to `limit` times per `window_s`, `backoff_s` after its death."""

    limit: int = 0
    window_s: float = 60.0
    backoff_s: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.limit, bool) or not isinstance(self.limit, int) or self.limit < 0:
            raise ValueError(f'limit must be an integer >= 0, got {self.limit!r}')
        for name in ('window_s', 'backoff_s'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not math.isfinite(value) or value < 0:
                raise ValueError(f'{name} must be a number >= 0, got {value!r}')

    def text(self) -> str:
        """'3 restarts per 60 s, 1 s back-off' or 'never restarted'."""
        if not self.limit:
            return 'never restarted'
        return (f'{self.limit} restart(s) per {self.window_s:g} s, {self.backoff_s:g} s back-off '
                'doubling')


DEFAULT_POLICIES: dict[str, RespawnPolicy] = {
    'context_estimator': RespawnPolicy(3, 60.0, 1.0),
    'policy': RespawnPolicy(3, 60.0, 1.0),
    'recorder': RespawnPolicy(3, 60.0, 0.5),
}
"""The bridges and the container (the loop itself) are never restarted unless asked."""


@dataclass
class RespawnState:
    """One node's restarts so far (monotonic times of its deaths)."""

    policy: RespawnPolicy
    deaths: list[float] = field(default_factory=list)

    def next_delay(self, now: float) -> float | None:
        """Seconds to wait before restarting after a death at `now`; None: give up."""
        self.deaths = [t for t in self.deaths if now - t <= self.policy.window_s]
        if len(self.deaths) >= self.policy.limit:
            return None
        self.deaths.append(now)
        return min(MAX_BACKOFF_S, self.policy.backoff_s * 2 ** (len(self.deaths) - 1))


def policies_from_params(params: Mapping[str, Any], nodes: Sequence[str],
                         base: Mapping[str, RespawnPolicy] = DEFAULT_POLICIES
                         ) -> dict[str, RespawnPolicy]:
    """The policies a params file (read_params' mapping) sets over `base`; ValueError names it.

    Reads `respawn: {node: {limit, window_s, backoff_s}}` from every `zeus_launch` section.
    """
    policies = dict(base)
    for key, section in params.items():
        if str(key).rstrip('/').rsplit('/', 1)[-1] != LAUNCH_SECTION:
            continue
        settings = (section or {}).get('ros__parameters') or {}
        unknown = sorted(set(settings) - {'respawn'})
        if unknown:
            raise ValueError(f'{key}: unknown setting(s) {unknown}; known: respawn')
        for node, fields in (settings.get('respawn') or {}).items():
            where = f'{key}: respawn.{node}'
            if node not in nodes:
                raise ValueError(f'{where}: no such node; nodes: {", ".join(nodes)}')
            if not isinstance(fields, Mapping):
                raise ValueError(f'{where}: expected {{limit: N, window_s: S, backoff_s: S}}')
            try:
                policies[node] = replace(policies.get(node, RespawnPolicy()), **fields)
            except (TypeError, ValueError) as error:
                raise ValueError(f'{where}: {error}') from None
    return policies


def parse_cli(values: Sequence[str], nodes: Sequence[str],
              base: Mapping[str, RespawnPolicy]) -> dict[str, RespawnPolicy]:
    """`--respawn NODE=LIMIT[/WINDOW_S[/BACKOFF_S]]` over `base`; ValueError names the flag."""
    policies = dict(base)
    for value in values:
        node, _, spec = value.partition('=')
        where = f'--respawn {value}'
        if node not in nodes or not spec:
            raise ValueError(f'{where}: expected NODE=LIMIT[/WINDOW_S[/BACKOFF_S]], NODE one of '
                             f'{", ".join(nodes)}')
        parts = spec.split('/')
        try:
            if len(parts) > 3:
                raise ValueError('at most LIMIT/WINDOW_S/BACKOFF_S')
            numbers: dict[str, Any] = {'limit': int(parts[0])}
            for name, text in zip(('window_s', 'backoff_s'), parts[1:], strict=False):
                numbers[name] = float(text)
            policies[node] = replace(policies.get(node, RespawnPolicy()), **numbers)
        except ValueError as error:
            raise ValueError(f'{where}: {error}') from None
    return policies
