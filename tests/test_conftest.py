"""The suite's own setup (tests/conftest.py): the queue of long work units names units that exist."""

from pathlib import Path

from conftest import LAST, UNIT_SECONDS

TESTS = Path(__file__).resolve().parent


def test_every_queued_unit_is_a_test_or_a_group_of_this_suite():
    """A renamed test or group silently loses its place at the head of the queue (and a long test started last
    keeps one worker busy alone): every key must name a test function or an ``xdist_group`` used by a test."""
    sources = {p.name: p.read_text() for p in TESTS.glob("*.py") if p.name != "conftest.py"}
    for unit in [*UNIT_SECONDS, *LAST]:
        if "::" in unit:
            path, name = unit.split("::")
            assert f"def {name}(" in sources[Path(path).name], unit
        else:
            assert any(f'"{unit}"' in text for text in sources.values()), unit  # a group's name, in a mark or helpers
