"""The ``cutkit`` command line: one small module per command, listed in :mod:`cutkit.cli.commands`."""
