"""The command-line interface ``duffid`` (argparse, one subcommand per job)."""
from .main import main

__all__ = ["main"]
