"""fbia.storage: the study store (SQLite) and what keys it.

``store`` (``StudyStore``: every finished run with its interfaces, its comparisons as layers),
``db`` (its SQLite connection; every error a one-line ``StoreError``), ``migration`` (older
stores re-keyed), ``fingerprints`` (what a run depends on, as digests) and ``output_folder``
(a study's output folder: its lock, what ``--fresh`` may delete).  It imports the kernel only.
"""
