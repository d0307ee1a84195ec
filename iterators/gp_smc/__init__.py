"""The ``gp_smc`` iterator (Paper B): the plugin (``iterator``: ``GpSmcIterator``), its options,
its result and figures (``result``, ``plots``), the record of a run shared by its stages
(``run``), the adaptive design (``adaptive``, ``adaptive_loop``) and the posterior's
statistics and files (``posterior``)."""
