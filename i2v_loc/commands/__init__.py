"""Subcommands of the ``i2v-loc`` command line."""
