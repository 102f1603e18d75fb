"""companion.nav."""
