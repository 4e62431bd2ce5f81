"""Your predictions, checked by pytest (as the chapter's `checks.py` are):

    pip install .                      # once, at the repository's top: the ratelab package
    python -m pytest exercises/        # every exercise you have predicted

Each exercise is one test. One you have not predicted yet is skipped (fill in its
[prediction] first: predicting is the exercise). One you have is run as `ratelab exercise
exN` runs it, and passes as the command passes (exit 0): it fails when your prediction
missed (a value other than the one measured, or an amount off by more than its sentence
allows), when it cannot be read (a key missing, or of the wrong type), or when one of the
exercise's checks fails. The failure's message sets each missed prediction beside the
outcome, in the words `ratelab exercise exN` prints; run that for the whole reconcile.
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
    wrong = [f"{p.key} ({p.verdict}): {p.said}" for p in found.missed]
    failed = [f"check failed: {c.name}" for c in found.failed_checks]
    assert found.passed and not wrong and not failed, f"{which} is not passed:\n" + "\n".join(
        wrong + failed
    )
