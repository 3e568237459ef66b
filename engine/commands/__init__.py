"""One module per `coach` subcommand: ``register(subparsers)`` and ``run(args)``."""
