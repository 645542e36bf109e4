"""The command-line tools (``kite-eval``, ``kite-train``, ``kite-bench``, ``kite-fit``, ``kite-polar``)."""

from __future__ import annotations

import argparse


def parse_or_status(p: argparse.ArgumentParser, argv) -> argparse.Namespace | int:
    """``p.parse_args(argv)``, or the exit status argparse chose: 0 after ``--help``, 2 after a parse error (its
    message already printed), so that a command's ``main`` returns it instead of raising ``SystemExit``."""
    try:
        return p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
