"""The discrepancy workflow: where simulation and measurement disagree, which effect is missing,
its parameters, and the gap before and after (DESIGN "The discrepancy workflow")."""
