"""The ``keepout`` command line: every subcommand, in one place.

``cli.main`` assembles the parser; each module here owns one subcommand (``add_cli(subparsers)`` adds its
parsers and sets ``func``) and calls into the library packages (gnc, comms, fsw, ground, hil_sim), none
of which imports this package. ``python -m cli`` is the same as ``keepout``.
"""


def description_of(doc: str) -> str:
    """A subcommand module's docstring after its first paragraph, for ``--help``: reST literals (double
    backticks) shown as plain text."""
    return doc.split("\n\n", 1)[1].replace("``", "")
