"""One module per ``translucent`` subcommand: ``add_arguments(parser)`` and ``run(args)``."""
