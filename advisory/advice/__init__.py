"""The advisor: feasible speeds, the DP lookup tables, the spoken wording."""
