"""fbia.plugins.fem: finite-element numerics shared by the forward-model plugins (no plugin
itself): a generic Newton solver on NGSolve matrices (:mod:`.newton`)."""
