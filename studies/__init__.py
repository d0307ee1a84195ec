"""fbia.studies: the study application.

A study file is read (``study_file``, ``study_schema``, ``study_oct``) into a ``Study``
(``study``), run by ``runner`` (``run_study``) on an evaluator from ``fbia.execution`` and a store
from ``fbia.storage``, and written out: tables, report, plots, provenance, progress, the
``[paper]`` comparison (``paper``, ``paper_report``), studies over noise draws (``draws``),
``fbia init`` (``study_template``) and the command line (``cli``).  It is the top layer: nothing
of fbia imports it except the package root.
"""
