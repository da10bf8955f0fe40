"""The tutorial notebook (docs/tutorial.ipynb) runs from top to bottom in a fresh kernel,
from an empty folder: it grows a plant, shows an image inline, exports a mesh and
measures the tree. CI also runs it from the built wheel outside the checkout."""

from __future__ import annotations

import os

import pytest
from _docs import DOCS, REPO

nbformat = pytest.importorskip("nbformat", reason="the notebook extra is not installed (pip install '.[notebook]')")
nbclient = pytest.importorskip("nbclient", reason="the notebook extra is not installed (pip install '.[notebook]')")
pytest.importorskip("ipykernel", reason="the notebook extra is not installed (pip install '.[notebook]')")

NOTEBOOK = DOCS / "tutorial.ipynb"


def test_the_tutorial_notebook_runs(tmp_path, monkeypatch, gl_ctx):
    if not NOTEBOOK.is_file():
        pytest.skip("needs the source tree's docs/tutorial.ipynb")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs), "the render shows no image inline"
    assert (tmp_path / "elm.glb").stat().st_size > 0
    figures = next(o["data"]["text/plain"] for o in outputs
                   if "'height'" in o.get("data", {}).get("text/plain", ""))
    height = float(figures.split("'height': ")[1].split(",")[0])
    assert 5 < height < 60          # an elm, in metres
