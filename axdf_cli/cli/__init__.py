"""The command-line layer: the only place that prints results or decides exit codes."""
