"""continual_trainer's operator services: pause/resume, a round now, the atomic pair swap.

Served on the trainer's spinning thread; the main thread's loop (continual_node.Trainer) reads
the flags at its next poll, so a service answers at once and never waits for a round.
"""

from __future__ import annotations

from typing import Any

from zeus_ros.nodes.pair_swap import PairSwapper
from zeus_ros.nodes.services import serve_swap, serve_switch, serve_trigger
from zeus_ros.system.continual_settings import append_history


class TrainerControls:
    """`~/pause` (SetBool), `~/run_round_now` (Trigger), `~/swap_checkpoint` (SwapCheckpoint)."""

    def __init__(self, node: Any) -> None:
        """`node`: the ContinualTrainer (its state, deployed checkpoint, history, report)."""
        self.node = node
        self.paused = False
        self.round_asked = False
        """Run a round at the next poll, whatever the count of new steps (then cleared)."""
        self.new_splits = 0
        """Closed splits since the last swap, as the last poll saw them."""
        self.swapped = False
        """An operator swapped the pair: the loop drops its live check of the round's swap."""
        self.swapper = PairSwapper(node)
        serve_switch(node, 'pause', self.pause)
        serve_trigger(node, 'run_round_now', self.run_round_now)
        serve_swap(node, 'swap_checkpoint', self.swap)

    def pause(self, pause: bool) -> str:
        """No new round starts while paused (a running one finishes; the live check goes on)."""
        was, self.paused = self.paused, pause
        self._record('pause' if pause else 'resume')
        if pause:
            return 'paused: no new round starts' + (' (already paused)' if was else '') + \
                (' (the running round finishes)' if self.node.state == 'training' else '')
        return 'resumed: rounds start again as new steps come' + ('' if was else
                                                                  ' (was not paused)')

    def run_round_now(self) -> str:
        """A round at the next poll on the closed splits there are, not waiting for new_steps."""
        if self.node.state == 'training':
            raise ValueError('a round is training now: ask again when it is done')
        if self.paused:
            raise ValueError('paused: resume first (~/pause false)')
        if self.new_splits == 0:
            raise ValueError('no closed split since the last swap yet: nothing new to train on')
        self.round_asked = True
        self._record('round_asked')
        return (f'a round starts within {self.node.p["poll_s"]:g} s on {self.new_splits} new '
                'closed split(s)')

    async def swap(self, checkpoint: str, expect_sha256: str) -> tuple[str, str]:
        """The pair onto `checkpoint` (pair_swap.py); the trainer deploys it from then on."""
        n = self.node
        if n.state == 'training':
            raise ValueError('a round is training now (it may swap itself): pause, wait for '
                             'it, then swap')
        message, sha256 = await self.swapper.swap(checkpoint, expect_sha256)
        n.previous, n.deployed = n.deployed, self.swapper.swapped_to
        self.swapped = True
        self._record('operator_swap', checkpoint=str(n.deployed), sha256=sha256)
        n.report('swap', f'continual: operator swapped in {n.deployed.name} ({sha256[:12]})')
        return message, sha256

    def _record(self, event: str, **fields: Any) -> None:
        append_history(self.node.history, {'event': event, 'by': 'operator', **fields})
