"""fbia.plugins: the built-in forward models, one sub-package each (``analytic``,
``ale_fsi``, ``cutfem_fpi``).  ``fbia.list_plugins()`` lists every installed plugin."""
