"""Sequential Monte Carlo (Paper B, Algorithm 1): the sampler (``sampler``: ``smc``,
``SmcResult``), its tempering schedule (``tempering``), the tabulated log-likelihood and its
compiled kernels (``table``, ``table_kernels``) and diagnostics."""
