"""HTTP routes: each module translates HTTP to ``service`` calls and nothing else."""
