"""fbia.plugins.growth: nutrient transport and surface growth on top of ``ale_fsi`` (issue 15)."""
