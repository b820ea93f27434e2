"""Contact-aware CasADi trajectory-optimisation retargeting (no torch)."""
