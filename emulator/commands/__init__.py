"""Subcommands of `lrf-emulator`, one module each: `add_arguments(parser)` and `run(args) -> int`."""
