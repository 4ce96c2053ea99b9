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

`ros2 launch zeus_ros zeus.launch.py` reads the same section (`LaunchRespawn`, `LaunchExits`):
launch_ros restarts a process `limit` times in all, `backoff_s` after each exit (it has no
window and no doubling), and the launch exits non-zero when a node of the loop died for good.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
import math
from typing import Any

__all__ = ['BAD_PARAMETERS', 'DEFAULT_POLICIES', 'LAUNCH_SECTION', 'ExitVerdict', 'LaunchExits',
           'LaunchRespawn', 'RespawnPolicy', 'RespawnState', 'parse_cli',
           'policies_from_params']

LAUNCH_SECTION = 'zeus_launch'
"""The params file section `zeus launch` reads its own settings from (no node has this name)."""
MAX_BACKOFF_S = 30.0
"""The delay before a restart doubles per restart in the window, up to this."""
BAD_PARAMETERS = 2
"""A node's exit status for parameters it refused at start (run_node): a restart would refuse
them again, so no launcher restarts it."""


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


@dataclass(frozen=True)
class LaunchRespawn:
    """launch_ros's respawn arguments for one process of `ros2 launch` (its Node keywords).

    launch_ros restarts a process after any exit while retries are left, `respawn_delay` s
    later; the retries count over the whole launch (`zeus launch` counts them in a window).
    """

    respawn: bool = False
    respawn_delay: float = 0.0
    respawn_max_retries: int = 0

    @classmethod
    def from_policy(cls, policy: RespawnPolicy) -> LaunchRespawn:
        """The closest launch_ros settings: `limit` restarts in all, `backoff_s` apart."""
        if not policy.limit:
            return cls()
        return cls(True, float(policy.backoff_s), policy.limit)

    def kwargs(self) -> dict[str, Any]:
        """Keyword arguments for launch_ros.actions.Node / launch.actions.ExecuteProcess."""
        if not self.respawn:
            return {'respawn': False}
        return {'respawn': True, 'respawn_delay': self.respawn_delay,
                'respawn_max_retries': self.respawn_max_retries}


@dataclass(frozen=True)
class ExitVerdict:
    """What `ros2 launch` does after a process exit: `action` and the line it logs.

    restart: launch_ros starts it again; go_on: the launch runs on without it; stop: the
    launch ends cleanly; fail: the launch ends and exits non-zero (a node died for good).
    """

    action: str
    message: str


@dataclass
class LaunchExits:
    """One process of `ros2 launch`: counts its exits and says what each one means.

    Mirrors `zeus launch`: a dead node of the control loop is restarted while its policy
    allows (the bridge applies its safe action meanwhile), then ends the launch with a
    failure; a refused configuration (exit 2) ends it at once; the recorder and the trainer
    (`background`) never stop the loop.
    """

    name: str
    respawn: LaunchRespawn = field(default_factory=LaunchRespawn)
    background: bool = False
    exits: int = 0

    def after_exit(self, code: int) -> ExitVerdict:
        """The verdict on one exit with status `code` (launch_ros has decided the same)."""
        self.exits += 1
        died = f'{self.name} exited with code {code}'
        retries = self.respawn.respawn_max_retries if self.respawn.respawn else 0
        if code == BAD_PARAMETERS and not self.background:
            return ExitVerdict('fail', f'{died}: it refused its parameters (see its error '
                               'line); a restart would refuse them too, the launch stops')
        if self.exits <= retries:
            meanwhile = '' if self.background else '; the loop runs on the safe action'
            return ExitVerdict('restart', f'{died}; restarting it in '
                               f'{self.respawn.respawn_delay:g} s (restart {self.exits} of '
                               f'{retries}{meanwhile})')
        after = f' after {retries} restart(s)' if retries else ''
        if self.background:
            rest = ('the rest of the run is not recorded' if self.name != 'continual_trainer'
                    else 'the loop runs on the checkpoint deployed last')
            return ExitVerdict('go_on', f'{died}{after}, not restarted again: {rest}')
        if code == 0:
            return ExitVerdict('stop', f'{died}{after}: the launch stops')
        why = after or ' (never restarted: its respawn policy)'
        return ExitVerdict('fail', f'{died}{why}: it died for good, the launch stops')
