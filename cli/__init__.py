"""The ``navtwin`` command line: the main, usage errors, signal handling, the bench registry
and every subcommand's argument parsing, each a thin layer over a Python API.

Layers below never import this package: library code raises its own one-line error types
(ScenarioError, ConfigError, RecordingError, ...) and the subcommands here turn them into
:class:`navtwin.cli.main.UsageError`, exit status 2. A subcommand is a module with
``register(subparsers)`` named in :data:`navtwin.cli.main.COMMANDS`; a user's package adds
one in the ``navtwin.commands`` entry-point group.
"""
