"""One SIL run: the orchestrator (three processes on one bus), the lockstep time keeper, the judge
(summary.json), estimator consistency and the run's plots."""
