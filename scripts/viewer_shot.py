"""Screenshot of a running headless rerun viewer (0.41) once a recording has loaded.

    python viewer_shot.py URL FILE.rrd OUT.png [--timeout-s 240]

`URL` is the viewer's `rerun+http://127.0.0.1:PORT/proxy` (a viewer started by
`scripts/viewer-shot.sh` with `--headless`). The viewer's own `--screenshot-to` takes its
picture a few frames after start, before the data of a larger recording has arrived (0.41 on
ratelab's files: the layout with empty views in most takes, VERIFIED.md). Here the picture
waits until the viewer says it has finished loading (its `loading` list empty, the recording's
timelines holding data) and its views have painted that data, through the viewer's control
API (`rerun.experimental.ViewerClient`, rerun 0.41).

Exit 0 with the picture written; 1 when the viewer did not load the recording in time, a view
reported an error, or no picture came (one line on stderr says which).
"""

from __future__ import annotations

import argparse
import sys
import time

from rerun.experimental import ViewerClient


def _connect(url: str, deadline: float) -> ViewerClient:
    """The viewer at `url`, once it answers (it may still be starting)."""
    last: Exception | None = None
    while time.monotonic() < deadline:
        try:
            client = ViewerClient.connect(url)
            client.get_state()
            return client
        except Exception as e:  # the viewer is not listening yet
            last = e
            time.sleep(0.25)
    raise TimeoutError(f"no viewer answered at {url}: {last}")


def _loaded(client: ViewerClient) -> tuple[bool, str]:
    """Whether the viewer shows a recording whose data has all arrived, and what it is at."""
    state = client.get_state()
    if state.loading:
        return False, "; ".join(s.status or s.name for s in state.loading)
    recordings = [r for r in state.recordings if r.store_id.startswith("Recording")]
    if not recordings:
        return False, "no recording open yet"
    if not any(t.end is not None for r in recordings for t in r.timelines):
        return False, "the recording has no data on its timelines yet"
    return True, "loaded"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url")
    parser.add_argument("rrd")
    parser.add_argument("out")
    parser.add_argument("--timeout-s", type=float, default=240.0)
    args = parser.parse_args()
    deadline = time.monotonic() + args.timeout_s
    client = _connect(args.url, deadline)
    client.open(args.rrd)
    status = "not asked yet"
    while time.monotonic() < deadline:
        done, status = _loaded(client)
        if done:
            break
        time.sleep(0.5)
    else:
        print(f"the viewer did not finish loading {args.rrd} in {args.timeout_s:.0f} s: {status}", file=sys.stderr)
        return 1
    # Loaded is not yet painted: software rendering draws a frame in about a second here, and
    # the views fill over the first frames after the data arrives. Two quiet seconds, then the
    # picture (save_screenshot waits for the next painted frame itself).
    time.sleep(2.0)
    errors = [
        f"{v.name}: {r.summary}"
        for v in client.get_state().views
        for r in v.reports
        if r.severity == "error"
    ]
    client.save_screenshot(args.out)
    if errors:
        print("views reported errors: " + "; ".join(errors), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
