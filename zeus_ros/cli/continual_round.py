"""`zeus continual-round`: one round of the live continual trainer, in its own process.

The continual_trainer node (zeus_ros/nodes/continual_node.py) writes a request (JSON) and runs
`python -m zeus_ros.cli continual-round --request FILE` for every round; this command runs
the library's round (offline/training/continual.py: `run_round`: rehearsal recording, train a
candidate, gate it, one `gate` line in history.jsonl) and writes the answer (JSON) to the
request's `result` path, atomically. The node never imports the training code, and each
round's memory goes back to the OS when this process ends.

Request: `deployed`, `first_checkpoint` (the rehearsal's), `rehearsal` (its folder),
`new_bags`, `splits`, `out` (the round's folder), `history`, `settings` (ContinualSettings
fields), `corrupt_rewards` and `forced` (the drills), `resume_from` (a refused candidate to
continue, or null), `teacher` (optional: the state teacher of a deployed pixel student; null:
the one its record names), `threads` (torch threads), `result`, and `parent_pid` (optional: the
round is killed when that process, the node, dies; it never outlives it). The round runs at
the priority it inherits (the node lowers its own with its `nice` parameter).
Answer: `status` 'done' (with run_round's fields: candidate, sha256, deploy, reason, gain,
se, required, summary, resume_from, episode_length; for a pixel student also
teacher_candidate, teacher_sha256 and teacher, the candidate then the refreshed student or
null), 'stopped' (SIGINT/SIGTERM during the
training: nothing written) or 'failed' (`error`: the exception's type, `reason`: its text;
the traceback goes to stderr). Log lines go to stdout (the node logs each one).
Exit code: 0 done, 1 failed, 2 a bad request, 3 stopped.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import sys
import threading
import traceback
from typing import Any

from zeus_ros.atomic_file import replace_text
from zeus_ros.cli_args import ZeusArgumentParser
from zeus_ros.system.processes import die_with_parent

__all__ = ['main']

EXIT = {'done': 0, 'failed': 1, 'stopped': 3}


def _die_with(parent: int | None) -> None:
    """SIGKILL when `parent` (the node) dies, as the round did when it ran inside the node."""
    if parent is None:
        return
    if not die_with_parent(signal.SIGKILL):  # not Linux: the node terminates it on shutdown
        return
    if os.getppid() != int(parent):  # it died before the line above
        os._exit(1)


def _round(request: dict[str, Any], stop: threading.Event) -> dict[str, Any]:
    import torch

    from zeus_ros.offline.training.continual import RoundStopped, run_round
    from zeus_ros.system.continual_settings import ContinualSettings

    torch.set_num_threads(max(1, int(request.get('threads', 1))))
    try:
        answer = run_round(
            request['deployed'], request['new_bags'], request['splits'], request['out'],
            request['history'], ContinualSettings(**request['settings']),
            first_checkpoint=request['first_checkpoint'], rehearsal_folder=request['rehearsal'],
            corrupt_rewards=bool(request['corrupt_rewards']), forced=bool(request['forced']),
            round_number=int(request.get('round', 0)), teacher=request.get('teacher'),
            start=request.get('resume_from'), log=lambda line: print(line, flush=True),
            stop=stop.is_set)
    except RoundStopped:
        return {'status': 'stopped'}
    except Exception as error:  # a bad split, a diverged candidate: the node logs and goes on
        traceback.print_exc()
        return {'status': 'failed', 'error': type(error).__name__, 'reason': str(error)}
    return {'status': 'done', **answer}


def main(argv: list[str] | None = None) -> int:
    """`zeus continual-round --request FILE`: run the round, write its answer, exit."""
    parser = ZeusArgumentParser(
        prog='zeus continual-round',
        description='One round of the live continual trainer (the continual_trainer node runs '
        "it in a child process): train a candidate on the request's splits, gate it against "
        'the deployed checkpoint, append the gate line to history.jsonl, and write the answer '
        "to the request's result path. SIGINT or SIGTERM stops the training (status stopped).")
    parser.add_argument('--request', type=Path, required=True,
                        help='the round request (JSON) the continual_trainer node wrote')
    args = parser.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        request = json.loads(args.request.read_text('utf8'))
        result_path = Path(request['result'])
    except (OSError, ValueError, KeyError, TypeError) as error:
        print(f'zeus continual-round: cannot read the request {args.request}: {error}',
              file=sys.stderr)
        return 2
    _die_with(request.get('parent_pid'))
    answer = _round(request, stop)
    replace_text(result_path, json.dumps(answer) + '\n')
    return EXIT[answer['status']]
