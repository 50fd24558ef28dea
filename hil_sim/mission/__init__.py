"""The mission file: its pydantic model, the YAML loader that reports every problem with its place, the
load-time physics checks and the generated reference (docs/missions.md)."""
