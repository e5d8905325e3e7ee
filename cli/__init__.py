"""The ``viewdb`` command line: a thin typer shell over the :mod:`viewdb` library."""
