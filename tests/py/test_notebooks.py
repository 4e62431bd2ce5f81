"""The notebooks in examples/notebooks/, executed headless (nbclient) in the environment the
wheel was installed into: every cell runs, and their last cells assert the chapter's figures
(5 Hz falls; a depth of 100 leaves the latency as it was)."""

from pathlib import Path

import pytest

nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")

NOTEBOOKS = Path(__file__).resolve().parents[2] / "examples" / "notebooks"


@pytest.mark.parametrize("name", sorted(p.name for p in NOTEBOOKS.glob("*.ipynb")))
def test_the_notebook_runs_and_its_checks_pass(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    notebook = nbformat.read(NOTEBOOKS / name, as_version=4)
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3").execute()
    # The plots were drawn (a figure's image is among the outputs where a cell plots).
    outputs = [o for c in notebook.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not any(o.get("output_type") == "error" for o in outputs)
    source = "".join(c.source for c in notebook.cells)
    if "plt." in source:
        assert any("image/png" in o.get("data", {}) for o in outputs)
    # rerun's viewer, inline: a widget (what a browser draws from it was not looked at here).
    if "Viewer(" in source:
        assert any("application/vnd.jupyter.widget-view+json" in o.get("data", {})
                   for o in outputs)


def test_there_are_notebooks():
    assert {p.name for p in NOTEBOOKS.glob("*.ipynb")} >= {
        "rate_cliff.ipynb", "your_own_brain.ipynb", "recording.ipynb"}


def test_a_node_class_from_a_cell_that_fails_names_the_cell_and_chains_its_error(tmp_path):
    # A learner's node class defined in a cell: the failure's line names the cell as IPython
    # does ("Cell In[1], line 8"), not the kernel's temporary file, and the class's own
    # exception, its traceback in the cell, is NodeFailed's cause.
    graph = Path(__file__).resolve().parents[2] / "graphs" / "cartpole-python.toml"
    cell = "\n".join([
        "import ratelab",
        "class Bad:",
        "    def __init__(self, node):",
        "        from ratelab import Force, State",
        "        self.pub = node.create_publisher(Force, '/action', 1)",
        "        node.create_subscription(State, '/obs', self.on_obs, 1)",
        "    def on_obs(self, msg):",
        "        raise ValueError('no good')",
    ])
    check = "\n".join([
        "try:",
        f"    ratelab.run(graph={str(graph)!r}, nodes={{'policy': Bad}}, duration_s=1.0,",
        "                clock='virtual')",
        "except ratelab.NodeFailed as e:",
        "    failed = e",
        "assert 'Cell In[1], line 8: ValueError: no good' in str(failed), str(failed)",
        "assert isinstance(failed.__cause__, ValueError), repr(failed.__cause__)",
    ])
    notebook = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell(cell), nbformat.v4.new_code_cell(check)])
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3").execute()


def test_a_brain_that_raises_in_a_notebook_shows_the_learner_s_frames_not_ratelab_s(tmp_path):
    # The traceback a notebook prints for NodeFailed: the brain's cell line, then the call
    # that ran it; neither ratelab's wrapper that called `act` (its `<ratelab>` frame) nor
    # the keyword check around `run` (hidden from IPython) is among its frames.
    import re

    cell = "\n".join([
        "import ratelab",
        "def act(obs):",
        "    return 1 / 0",
        "ratelab.run(policy=act, duration_s=1, clock='virtual')",
    ])
    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(cell)])
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3",
                            allow_errors=True).execute()
    error = next(o for o in notebook.cells[0].outputs if o.get("output_type") == "error")
    assert error["ename"] == "NodeFailed", error["ename"]
    shown = "\n".join(re.sub(r"\x1b\[[0-9;]*m", "", line) for line in error["traceback"])
    assert "Cell In[1], line 3, in act" in shown, shown
    assert "<ratelab>" not in shown, shown
    assert "checked" not in shown and "skipping hidden 1 frame" in shown, shown
