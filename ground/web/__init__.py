"""``keepout ground web``: Open MCT with a keepout plugin, served over a run's telemetry and archive."""
