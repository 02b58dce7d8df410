"""Subcommands of the fdikit CLI, one module each (see fdikit.cli)."""
