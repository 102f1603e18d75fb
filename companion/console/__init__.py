"""companion.console."""
