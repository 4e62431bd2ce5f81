"""Every example in the package's docstrings runs and prints what it says (#71): the
docstrings' `>>>` lines, run by doctest against the installed package."""

import doctest
from pathlib import Path

import pytest

import ratelab

ROOT = Path(__file__).resolve().parents[2]


def examples():
    return [t for t in doctest.DocTestFinder().find(ratelab) if t.examples]


def test_the_docstrings_have_examples():
    names = {t.name for t in examples()}
    assert {"ratelab", "ratelab.run", "ratelab.sweep", "ratelab.cliff"} <= names, names


@pytest.mark.parametrize("test", examples(), ids=lambda t: t.name)
def test_every_docstring_example_runs(test, monkeypatch):
    # Paths in the examples are the repository's, as the tests' are.
    monkeypatch.chdir(ROOT)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report = []
    runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)
