"""JSON Schema files of the command-line contract (read through :mod:`lab.contract`)."""
