"""The ``keepout`` command line: every subcommand, in one place.

``cli.main`` assembles the parser; each module here owns one subcommand (``add_cli(subparsers)`` adds its
parsers and sets ``func``) and calls into the library packages (gnc, comms, fsw, ground, hil_sim), none
of which imports this package. ``python -m cli`` is the same as ``keepout``.
"""


def description_of(doc: str) -> str:
    """A subcommand module's docstring after its first paragraph, for ``--help``: reST literals (double
    backticks) shown as plain text."""
    return doc.split("\n\n", 1)[1].replace("``", "")


def udp_port(text: str) -> int:
    """argparse type: a UDP port number 1..65535 (a clear error instead of a traceback later)."""
    import argparse

    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number; allowed: 1..65535") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a UDP port; allowed: 1..65535")
    return port


def udp_port_or_zero(text: str) -> int:
    """argparse type: a port to bind, 0..65535 (0: the kernel picks a free one)."""
    return 0 if text.strip() == "0" else udp_port(text)
