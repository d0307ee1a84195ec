"""The insides of ``surrogate_convergence`` (Paper B, Fig. 8 and Fig. 12): its result and
plots."""
