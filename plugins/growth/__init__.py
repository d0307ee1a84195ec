"""fbia.plugins.growth: nutrient transport, Monod consumption and surface growth on top of
``ale_fsi`` (Paper A, eq. 5-9, the growth example).

Modules: :mod:`.transport` (the nutrient field Phi on the ALE mesh: advection-diffusion in the
fluid, diffusion and Monod consumption in the biofilm, steady and backward-Euler steps, the
interface flux h of eq. 7 and the global nutrient balance).  Importing this package is cheap:
NGSolve is imported only when a solver is built.
"""
