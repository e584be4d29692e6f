"""pytest plugin: fixtures that start an emulated lab (registered via pytest11)."""
