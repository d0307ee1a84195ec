"""Gaussian-process surrogates of the log-likelihood (Paper B): the GP (``gp``), its kernels,
trend (prior mean, ``mean``, ``trend``), the guard against a surrogate far off its data,
the failure classifier (``feasibility``), the residual emulator (``residuals``), the Sobol
design (``design``) and the GP's own uncertainty (``uncertainty``)."""
