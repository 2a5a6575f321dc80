"""The discrepancy workflow: where simulation and measurement disagree, which effect is missing,
its parameters, and the gap before and after (README "Simulate, then explain the difference")."""
