"""``plantgen batch``: many plants on Dask (dask.distributed), as labelled datasets.

:mod:`~plantgen.batch.spec` reads what to make (grammars × seed indices × sweeps over
their defines, and the outputs), :mod:`~plantgen.batch.plant` makes one plant in a worker,
:mod:`~plantgen.batch.manifest` keeps the Parquet manifest, :mod:`~plantgen.batch.engine`
runs the tasks on a cluster. Dask and pyarrow are the ``batch`` extra, imported only when a
batch runs.
"""

from .engine import BatchResult, run_batch, summary_lines
from .spec import BatchError, BatchSpec, Outputs, PlantTask, parse_spec, plant_seed, simple_spec

__all__ = ["BatchError", "BatchResult", "BatchSpec", "Outputs", "PlantTask", "parse_spec", "plant_seed",
           "run_batch", "simple_spec", "summary_lines"]
