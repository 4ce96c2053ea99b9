"""The `zeus` command: one entry point for the record -> retrain -> redeploy loop.

Each subcommand lives in its own module with a `main(argv) -> int` (the command line of a
library function, or of the live system in zeus_ros/system/): zeus_ros/cli/<command>.py, all
of them here (`zeus inspect` is inspect_topics.py, `zeus eval` evaluate.py); this file only
dispatches, so `zeus --help` stays fast (heavy imports happen inside the chosen subcommand).
"""

from __future__ import annotations

import importlib
import sys

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    'collect': ('zeus_ros.cli.collect',
                'run a task in-process and write bags (no ROS)'),
    'ingest': ('zeus_ros.cli.ingest',
               'read bags as training does; report what they hold'),
    'bags': ('zeus_ros.cli.bags',
             'list bags: kind (manual, collected, continual, rehearsal), task, steps, when'),
    'train': ('zeus_ros.cli.train', 'train a checkpoint from bags'),
    'eval': ('zeus_ros.cli.evaluate', 'evaluate checkpoints in-process (+ tables)'),
    'adaptation': ('zeus_ros.cli.adaptation',
                   "a checkpoint's value of adaptation next to the zoo's"),
    'report': ('zeus_ros.cli.report',
               'mean ± s.e. over seeds of evaluations; a continual run over time'),
    'export': ('zeus_ros.cli.export', 'small deployment checkpoint + card'),
    'distill': ('zeus_ros.cli.distill',
                'a pixel student from a state teacher (DAgger rounds, no RL)'),
    'loop': ('zeus_ros.cli.loop', 'random collection -> train -> collect -> retrain'),
    'sweep': ('zeus_ros.cli.sweep', 'tasks x methods x seeds of loop + eval on Ray'),
    'launch': ('zeus_ros.cli.launch', 'start sim_bridge, context_estimator, policy (+recorder)'),
    'inspect': ('zeus_ros.cli.inspect_topics', 'live view of the context topics (subscribe only)'),
    'recover': ('zeus_ros.cli.recover', 'restore a bag cut off by a crash'),
    'demo': ('zeus_ros.cli.demo', 'the live demo of the README'),
    'continual-round': ('zeus_ros.cli.continual_round',
                        "one round of the continual trainer (the node's child process)"),
}
INTERNAL = frozenset({'continual-round'})
"""Commands other programs run (the continual trainer node its rounds): they dispatch like the
others but stay out of `zeus --help`, which lists what a user types."""


def usage() -> str:
    """The top-level help text: the user's commands."""
    lines = ['usage: zeus <command> [options]', '', 'commands:']
    shown = {name: entry for name, entry in SUBCOMMANDS.items() if name not in INTERNAL}
    width = max(10, *map(len, shown))
    lines += [f'  {name:<{width}} {summary}' for name, (_module, summary) in shown.items()]
    lines += ['', "run 'zeus <command> --help' for a command's options"]
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the chosen subcommand and return its exit code."""
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] in ('-h', '--help'):
        print(usage())
        return 0
    name, rest = args[0], args[1:]
    if name not in SUBCOMMANDS:
        print(f'zeus: unknown command {name!r}\n\n{usage()}', file=sys.stderr)
        return 2
    module = importlib.import_module(SUBCOMMANDS[name][0])
    return int(module.main(rest) or 0)

