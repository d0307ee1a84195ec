"""fbia.execution: where forward runs happen.

The evaluator's front part (``evaluator``: numbering, run cache, folders, listeners), the run
cache in front of the store (``cache``), the executors (``local_executors``: serial and process
pool; ``dask_executor``), the child process of a run (``isolation``), the factory by name
(``executors.make_evaluator``), the Dask cluster options a study may set
(``cluster_options``) and what the machine can hold (``resources``).  It imports the kernel
(``fbia.core``) and the store (``fbia.storage``), never the study application.
"""
