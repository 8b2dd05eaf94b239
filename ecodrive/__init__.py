"""The ``ecodrive`` command line: one entry point for the project's commands (see :mod:`ecodrive.cli`).

The commands' code lives with what they work on (``server.main``, ``replay.cli``, the study); this package
only names and dispatches them.
"""
