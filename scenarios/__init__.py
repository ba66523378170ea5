"""Scenarios: one module per scenario family; each registers its scenarios
with :func:`bench.registry.register_scenario`."""
