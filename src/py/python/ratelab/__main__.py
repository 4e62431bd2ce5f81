"""`ratelab …` and `python -m ratelab …`: ratelab's whole command line (the lab, `run`,
`launch`, `exercise`, …) in this interpreter. A launch starts its processes the same way."""

import sys

from . import _native


def main() -> None:
    """The `ratelab` command: exits with the command line's code (0 done, 1 an exercise not
    passed, 2 bad input or a failed run, 130 interrupted)."""
    sys.exit(_native.main(["ratelab", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
