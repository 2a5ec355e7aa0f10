"""The example notebook (examples/notebooks/api.ipynb) runs from top to bottom: the public
API (``from bestofn_swarm import run, sweep``) as a reader of docs/extending.md meets it,
with the example plug-in. It needs the ``notebook`` extra (nbclient, ipykernel, pandas) and
the example plug-in installed; it says which is missing and skips without them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
NOTEBOOK = REPO / "examples" / "notebooks" / "api.ipynb"
NEEDS = {
    "nbclient": "pip install -e '.[notebook]'",
    "nbformat": "pip install -e '.[notebook]'",
    "ipykernel": "pip install -e '.[notebook]'",
    "pandas": "pip install -e '.[notebook]'",
    "bestofn_linear_pool": "pip install -e examples/linear_pool",
}

pytestmark = pytest.mark.timeout(600)


def test_the_example_notebook_runs_and_shows_what_it_says() -> None:
    missing = [name for name in NEEDS if importlib.util.find_spec(name) is None]
    if missing:
        pytest.skip(f"the notebook needs {', '.join(missing)}: {NEEDS[missing[0]]}")
    import nbclient
    import nbformat

    notebook = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(
        notebook, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(REPO)}}
    ).execute()
    outputs = [
        "".join(
            output.get("text", "") or output.get("data", {}).get("text/plain", "")
            for output in cell.get("outputs", [])
        )
        for cell in notebook.cells
        if cell.cell_type == "code"
    ]
    errors = [
        output for cell in notebook.cells for output in cell.get("outputs", [])
        if output.get("output_type") == "error"
    ]  # fmt: skip
    assert errors == []
    assert "('consensus'" in outputs[1]
    assert "decided" in outputs[2] and "p_best_mean" in outputs[2]
    assert "'distribution': 'bestofn-linear-pool'" in outputs[4]
    assert "linear" in outputs[6] and "mprodop" in outputs[6]
