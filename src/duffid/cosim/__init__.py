"""Co-simulation of FMUs: the system spec and its elements, the fixed-step runner, the
container export and system files."""
