"""The insides of ``levenberg_marquardt`` (Paper A): one start's ask/tell chains (``chains``:
``LMChain``, ``PaperChain``; ``robust``: ``RobustChain``), the step (``trust_region``), the
Jacobian's stencils (``finite_differences``), options, result statistics, plots and the hand-off
from a ``gp_smc`` posterior (``handoff``)."""
