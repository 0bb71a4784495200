"""Outputs change only on purpose: every golden case (tests/golden.py) writes the bytes whose
digest is committed in tests/fixtures/golden.json."""

from __future__ import annotations

import json

import pytest

from golden import DIGESTS, cases, compute

EXPECTED = json.loads(DIGESTS.read_text())


def test_golden_cases_are_the_committed_ones():
    assert sorted(cases()) == sorted(EXPECTED)


@pytest.fixture(scope="module")
def actual():
    return compute()


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_output_bytes_unchanged(actual, name):
    assert actual[name] == EXPECTED[name], (
        f"{name} changed; if intended, run `python tests/golden.py --update` in its own commit"
    )
