"""One module per `host` subcommand.

Each module defines `add_parser(subparsers)`, which registers its subcommand and sets
`func=run` on the parser, and `run(args) -> int`. `host.cli` discovers the modules here, so a
new command is one new file.
"""
