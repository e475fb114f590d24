"""The subcommands of the `gyrojax` command line (`gyrojax/cli.py`), one per file: its parser (`add_parser`)
and its handler (`handle`); `common.py` holds what they share."""
