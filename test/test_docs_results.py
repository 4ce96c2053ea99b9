"""docs/results.md stays a reader's index, and the README's demo counts are the demo's (issue 52).

The index answers by question and links to the pages that hold the detail: it must stay short
enough to read (<= 400 lines) and every link in it, and in the pages it moved detail to, must
open. The README's demo sentence counts segments; they follow from the demo's schedule, so a
change of the schedule that leaves the README behind fails here instead of misleading a reader.
"""

from __future__ import annotations

from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'docs' / 'results.md'
MAX_RESULTS_LINES = 400
MOVED_PAGES = (ROOT / 'docs' / 'results' / 'heldout' / 'README.md',
               ROOT / 'docs' / 'results' / 'what_did_not_work.md')
"""The pages that took questions 6 and 7's tables out of the index."""

_LINK = re.compile(r'!?\[[^\]]*\]\(([^)\s]+)(?:\s+"[^"]*")?\)')


def _links(text: str) -> list[str]:
    """Markdown link and image targets outside code blocks."""
    prose = re.sub(r'```.*?```', '', text, flags=re.DOTALL)
    return _LINK.findall(prose)


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r'[^\w\- ]', '', heading.strip().lower()).replace(' ', '-')


def _anchors(path: Path) -> set[str]:
    text = re.sub(r'```.*?```', '', path.read_text(), flags=re.DOTALL)
    return {_anchor(m) for m in re.findall(r'^#+\s+(.*)$', text, flags=re.MULTILINE)}


def test_results_index_stays_short() -> None:
    """The index holds summaries and links; long tables live on the linked pages."""
    lines = RESULTS.read_text().splitlines()
    assert len(lines) <= MAX_RESULTS_LINES, (
        f'docs/results.md has {len(lines)} lines (at most {MAX_RESULTS_LINES}): move long tables '
        'or bullet lists to a page under docs/results/ named by the question, and link it')


@pytest.mark.parametrize('page', [RESULTS, *MOVED_PAGES], ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_opens(page: Path) -> None:
    """Each relative link names an existing file, and each #anchor an existing heading."""
    broken = []
    for target in _links(page.read_text()):
        if re.match(r'^[a-z][a-z0-9+.-]*:', target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition('#')
        file = (page.parent / path_part).resolve() if path_part else page
        if not file.exists():
            broken.append(f'{target}: no such file')
        elif anchor and file.suffix == '.md' and anchor not in _anchors(file):
            broken.append(f'{target}: no heading with anchor #{anchor} in {file.name}')
    assert not broken, broken


def test_results_index_links_its_moved_detail() -> None:
    """The pages that hold questions 6 and 7's tables are reachable from the index."""
    targets = {(RESULTS.parent / target.partition('#')[0]).resolve()
               for target in _links(RESULTS.read_text())}
    assert set(MOVED_PAGES) <= targets


def test_readme_demo_counts_are_the_demos() -> None:
    """60 paired segments, 30 on training values and 30 beyond: from the demo's own schedule.

    The demo (zeus_ros/cli/demo.py) runs `--seeds` schedule seeds of `schedule_lengths` steps,
    switching every `every` steps through `schedule_values` in order; its summary keeps the
    segments that ran the full `every` steps and splits them by the family's train values.
    """
    from zeus_ros.cli import demo

    every, steps = demo.schedule_lengths(demo.DEFAULT_TASK)
    values = demo.schedule_values(demo.DEFAULT_TASK)
    assert isinstance(values, list)
    train = {tuple(round(v, 9) for v in value) for value in demo.train_values(demo.DEFAULT_TASK)}
    seeds = 3  # `zeus demo --seeds` default (the next test checks --help)
    periods = range(steps // every)  # a shorter last segment is dropped by the summary
    on_train = sum((round(values[p % len(values)], 9),) in train for p in periods) * seeds
    total = len(periods) * seeds
    readme = ' '.join((ROOT / 'README.md').read_text().split())
    expected = (f'{total} segments, {on_train} on training values and {total - on_train} '
                'beyond')
    assert expected in readme, f'README.md should say "{expected}" of `make demo`'


def test_demo_seeds_default_is_what_the_readme_counts(capsys: pytest.CaptureFixture[str]) -> None:
    """The count above assumes 3 schedule seeds: the default `zeus demo --help` states."""
    from zeus_ros.cli import demo

    with pytest.raises(SystemExit):
        demo.main(['--help'])
    help_text = ' '.join(capsys.readouterr().out.split())
    assert re.search(r'--seeds SEEDS schedule seeds, .*default 3\)', help_text), help_text
