"""Ways of generating situations, judged by what they find: the seeded-fault yardstick
(faults), controller diffs (diff) and search (MAP-Elites, coverage-guided)."""
