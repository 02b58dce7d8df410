"""Subcommands of the ``fdikit`` command, one module each with ``register(subparsers)`` (see
:mod:`fdikit.cli`). Not a library API: use the packages they call."""

__all__: list[str] = []
