"""One module per `perchd` subcommand; see perchd.cli."""
