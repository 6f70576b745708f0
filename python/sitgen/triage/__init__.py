"""Making sense of stored runs: a run whole again (recall), its robustness under perturbation,
the kill rule, distinct failures, ranking, situation coverage, learned weights and
shrinking."""
