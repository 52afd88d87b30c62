"""The ``duffid-cli`` directive: the command-line reference generated from duffid's argparse
parsers (``duffid.cli.build_parser``), one section per subcommand.

Help strings are plain text (what ``--help`` prints), so they are shown as text, never parsed
as reStructuredText: a ``|x|`` or a trailing ``::`` in a help string stays as written.
"""
from __future__ import annotations

import argparse

from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.application import Sphinx

__all__ = ["CliReference", "setup"]


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The action's help with ``%(default)s`` and the like expanded, as ``--help`` prints it."""
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return parser._get_formatter()._expand_help(action)


def _options(parser: argparse.ArgumentParser) -> nodes.definition_list:
    items = nodes.definition_list()
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.option_strings:
            metavar = "" if action.nargs == 0 else " " + (
                parser._get_formatter()._format_args(action, action.dest.upper()))
            names = ", ".join(f"{o}{metavar}" for o in action.option_strings)
        else:
            names = parser._get_formatter()._format_args(action, action.dest)
        term = nodes.term("", "", nodes.literal(names, names))
        body = nodes.definition("", nodes.paragraph("", _help(parser, action) or "(no description)"))
        items += nodes.definition_list_item("", term, body)
    return items


class CliReference(Directive):
    """``.. duffid-cli::``: the usage and options of ``duffid`` and every subcommand."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from duffid.cli import build_parser

        parser = build_parser()
        out: list[nodes.Node] = [nodes.literal_block(parser.format_usage(), parser.format_usage())]
        if parser.description:
            out.append(nodes.paragraph("", parser.description))
        for name, sub in _subcommands(parser).items():
            section = nodes.section(ids=[f"duffid-{name}"], names=[f"duffid {name}"])
            section += nodes.title("", "", nodes.literal(f"duffid {name}", f"duffid {name}"))
            if sub.description:
                section += nodes.paragraph("", sub.description)
            usage = sub.format_usage().strip()
            section += nodes.literal_block(usage, usage)
            section += _options(sub)
            if sub.epilog:
                section += nodes.paragraph("", sub.epilog)
            out.append(section)
        return out


def setup(app: Sphinx) -> dict[str, bool]:
    app.add_directive("duffid-cli", CliReference)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
