"""Your predictions, checked by pytest (as the chapter's `checks.py` are):

    pip install .                      # once, at the repository's top: the ratelab package
    python -m pytest exercises/        # every exercise you have predicted

Each exercise is one test. One you have not predicted yet is skipped (fill in its
[prediction] first: predicting is the exercise). One you have is run as `ratelab exercise
exN` runs it, and fails when one of its checks fails or your prediction cannot be read (a
key missing, or of the wrong type) — a prediction that turned out wrong is no failure: read
the reconcile that the failure message and `ratelab exercise exN` print beside it.
"""

from pathlib import Path

import pytest

import ratelab

HERE = Path(__file__).resolve().parent


@pytest.mark.parametrize("which", [e["id"] for e in ratelab.exercises()])
def test_exercise(which):
    try:
        found = ratelab.exercise(which, dir=HERE)
    except ratelab.NoPrediction as e:
        pytest.skip(str(e))
    failed = [c.name for c in found.checks if not c.passed]
    assert not failed, f"{which}: checks that failed: {failed}"
    assert found.passed, f"{which}: " + " ".join(found.reconcile)
